#!/usr/bin/env bash
# The README tour's pictures (docs/src/images/tour-*.svg), made by the tour's own commands on
# the shared records and the QEMU firmware. Run from anywhere: bash docs/images.sh
set -euo pipefail
cd "$(dirname "$0")/.."
D="${PIEZO_DATA:-$(cd .. && pwd)/shared/data}"
cargo build --release -p hal-sim --bin piezo
P=target/release/piezo
out=out/tour
img=docs/src/images
mkdir -p "$img"
# The plots keep up to 4000 points per line, more than a 550-pixel panel shows: each path is
# simplified to within 0.25 pixel (Ramer-Douglas-Peucker), coordinates to 0.1 pixel; scatter
# dots that fall on the same pixel are drawn once, as one path per colour.
thin() {
  python3 - "$1" "$2" <<'PY'
import re, sys
def rdp(pts, eps):
    keep, stack = [0, len(pts) - 1], [(0, len(pts) - 1)]
    while stack:
        a, b = stack.pop()
        (x1, y1), (x2, y2) = pts[a], pts[b]
        dx, dy = x2 - x1, y2 - y1
        n = (dx * dx + dy * dy) ** 0.5
        best, far = -1.0, None
        for i in range(a + 1, b):
            x, y = pts[i]
            d = abs(dy * (x - x1) - dx * (y - y1)) / n if n else ((x - x1) ** 2 + (y - y1) ** 2) ** 0.5
            if d > best:
                best, far = d, i
        if far is not None and best > eps:
            keep.append(far)
            stack += [(a, far), (far, b)]
    return [pts[i] for i in sorted(set(keep))]
def path(m):
    segs, out = re.findall(r"([ML])([-0-9.]+),([-0-9.]+)", m.group(1)), []
    run = []
    def flush():
        if run:
            for j, (x, y) in enumerate(rdp(run, 0.25)):
                out.append(("M" if j == 0 else "L") + f"{x:.1f},{y:.1f}")
    for c, x, y in segs:
        if c == "M":
            flush()
            run = []
        run.append((float(x), float(y)))
    flush()
    return 'd="' + " ".join(out) + '"'
dots = {}
def dot(m):
    r, fill = float(m.group(3)), m.group(4)
    pts = dots.setdefault((r, fill), {})
    pts[(round(float(m.group(1))), round(float(m.group(2))))] = None
    return "\0" if len(dots) + sum(map(len, dots.values())) == 2 else ""
src = open(sys.argv[1]).read()
src = re.sub(r'd="([^"]*)"', path, src)
src = re.sub(r'<circle cx="([-0-9.]+)" cy="([-0-9.]+)" r="([0-9.]+)" fill="([^"]*)"/>', dot, src)
# Each colour's dots as one path of round-capped zero-length strokes (a dot each).
src = src.replace("\0", "".join(
    f'<path d="{"".join(f"M{x} {y}h0" for x, y in pts)}" stroke="{fill}" '
    f'stroke-width="{2 * r}" stroke-linecap="round"/>' for (r, fill), pts in dots.items()))
open(sys.argv[2], "w").write(src)
PY
}
rm -rf "$out"
# 1. simulate
"$P" sim --scenario sine-10hz --controller open-loop --controller hgo-robust --out "$out/sim"
thin "$out/sim/sine-10hz_hgo-robust.svg" "$img/tour-sim.svg"
# 2. flash: the QEMU firmware's capture of a 5 um, 100 Hz sine (35-host-serial.sh's session)
PIEZO_BIN=$P PIEZO_SERIAL_OUT="$out/serial" bash .ci/test.d/35-host-serial.sh >/dev/null
thin "$out/serial/rec.svg" "$img/tour-flash.svg"
# 3. identify
"$P" fit --model cbw --train "$D/smarthysteresis-piezo/piezo_150V_1Hz.csv" --split 0.6 \
  --out "$out/fit" --quiet
thin "$out/fit/valid_y.svg" "$img/tour-fit.svg"
# 4. diagnose
"$P" diagnose --train "$D/smarthysteresis-piezo/piezo_150V_1Hz.csv" \
  --train-window 3.26:6.26 --valid-window 6.26: --out "$out/diagnose"
thin "$out/diagnose/diagnose.svg" "$img/tour-diagnose.svg"
ls -l "$img"
