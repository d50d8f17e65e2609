#!/usr/bin/env python3
"""What a mirror model gets wrong, by frequency band and level (docs/src/lfr.md).

    python3 docs/lfr-residual.py FIT_JSON [--piezo target/host/piezo] [--data ../shared/data/fsm-benchmark]
        [--records 1,2,3,4]

Simulates the model on each record of each level with `piezo predict` (one period of
warm-up, as the benchmark's rule), takes the residual's spectrum (mean of the two
periods) and, in blocks of 8 neighbouring lines pooled over the records, fits a linear
error dG (3 inputs to each output) by least squares: per level, across all levels at once,
and affine in the level. Printed per band: the residual's power and the share a per-level
and a joint dG explain. With random-phase multisines nonlinear distortion is incoherent
across realizations, so a share well above chance (inputs / equations: 3/32 per level) is
a linear error of the model; one the joint dG does not explain changes with the level.
Needs numpy.
"""
import argparse
import os
import subprocess
import tempfile

import numpy as np

P, FS, LINES = 8192, 6400.0, 8
BANDS = [0, 400, 800, 1000, 1250, 1450, 2000, 2200, 3000, 3200]


def residual(piezo, fit, path, tmp):
    a = np.loadtxt(path, delimiter=",", comments="#", skiprows=3)
    u, y = a[:, 1:4], a[:, 4:7]
    uu = np.vstack([u[P:2 * P], u])  # one period of warm-up
    t = np.arange(len(uu)) / FS
    inp, out = os.path.join(tmp, "in.csv"), os.path.join(tmp, "out.csv")
    np.savetxt(inp, np.column_stack([t, uu]), delimiter=",", header="t,u1,u2,u3",
               comments="", fmt="%.9g")
    subprocess.run([piezo, "predict", "--model", fit, "--input", inp, "--out", out],
                   check=True, capture_output=True)
    m = np.loadtxt(out, delimiter=",", skiprows=2)[P:, 1:4]
    e = y - m
    return np.fft.rfft((e[:P] + e[P:]) / 2, axis=0), np.fft.rfft(u[:P], axis=0)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("fit")
    ap.add_argument("--piezo", default="target/host/piezo")
    ap.add_argument("--data", default="../shared/data/fsm-benchmark")
    ap.add_argument("--records", default="1,2,3,4")
    a = ap.parse_args()
    recs = [int(r) for r in a.records.split(",")]
    levels = (100, 200, 300)
    with tempfile.TemporaryDirectory() as tmp:
        rs = [[residual(a.piezo, a.fit, f"{a.data}/fsm_{lv}mV_r{r}.csv", tmp) for r in recs]
              for lv in levels]
    f = np.arange(P // 2 + 1) * FS / P
    nb = len(BANDS) - 1
    tot, per, joint = (np.zeros((3, nb)) for _ in range(3))
    for k0 in range(1, P // 2 - LINES, LINES):
        idx = list(range(k0, k0 + LINES))
        us = [np.vstack([r[1][idx] for r in lv]) for lv in rs]
        es = [np.vstack([r[0][idx] for r in lv]) for lv in rs]
        gj = np.linalg.lstsq(np.vstack(us), np.vstack(es), rcond=None)[0]
        b = min(np.searchsorted(BANDS, f[k0], side="right") - 1, nb - 1)
        for i in range(3):
            g = np.linalg.lstsq(us[i], es[i], rcond=None)[0]
            e2 = (np.abs(es[i]) ** 2).sum()
            tot[i, b] += e2
            # What a dG removes: |E|^2 - |E - U dG|^2 (for the level's own LS fit, |U dG|^2).
            per[i, b] += e2 - (np.abs(es[i] - us[i] @ g) ** 2).sum()
            joint[i, b] += e2 - (np.abs(es[i] - us[i] @ gj) ** 2).sum()
    scale = tot.sum() / 100.0
    print("band (Hz)    residual power (% of all levels' total)   share a linear error explains: "
          "per level / joint")
    print("             100 mV  200 mV  300 mV                    100 mV     200 mV     300 mV")
    for b in range(nb):
        p = " ".join(f"{tot[i, b] / scale:7.1f}" for i in range(3))
        s = "  ".join(f"{per[i, b] / tot[i, b]:.2f}/{joint[i, b] / tot[i, b]:.2f}" for i in range(3))
        print(f"{BANDS[b]:5d}-{BANDS[b + 1]:5d}  {p}                    {s}")
    s = "  ".join(f"{per[i].sum() / tot[i].sum():.2f}/{joint[i].sum() / tot[i].sum():.2f}"
                  for i in range(3))
    print(f"all          (chance: {3 / (LINES * len(recs)):.2f} per level)                      {s}")


if __name__ == "__main__":
    main()
