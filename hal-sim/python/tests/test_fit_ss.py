"""fit() of the state-space models (`ss`, `lfr`): the same model as `piezo fit` saves for
the same records, usable with predict()."""
import json

import numpy as np
import pytest

import piezo

PERIOD, FS = 512, 1000.0


def _record(path, seed, amp):
    """Two steady periods of a random-phase multisine of RMS `amp` through a lightly
    damped mode with a softening cubic in feedback (`t,u1,y1`)."""
    rng = np.random.default_rng(seed)
    k = np.arange(PERIOD)
    one = sum(np.cos(2 * np.pi * l * k / PERIOD + rng.uniform(0, 2 * np.pi))
              for l in range(1, 60))
    one *= amp / np.sqrt(np.mean(one ** 2))
    u = np.tile(one, 3)
    x = np.zeros(2)
    y = np.zeros_like(u)
    for i, ui in enumerate(u):
        y[i] = x[0]
        w = -0.05 * x[0] ** 3
        x = np.array([1.6 * x[0] - 0.81 * x[1] + 0.3 * ui + w, x[0]])
    u, y = u[PERIOD:], y[PERIOD:]
    t = np.arange(len(u)) / FS
    np.savetxt(path, np.column_stack([t, u, y]), delimiter=",", header="t,u1,y1",
               comments="", fmt="%.12g")
    return path


def _model(j):
    """The saved model without the report (timings, file names)."""
    return {k: v for k, v in j.items() if k != "report"}


@pytest.mark.parametrize("model,extra", [
    ("ss", ["--order", "2"]),
    ("lfr", ["--order", "2", "--lfr-iterations", "3", "--lm-iterations", "20",
             "--input-delay", "1"]),
])
def test_the_state_space_fit_is_the_clis(tmp_path, piezo_cli, model, extra):
    train = [_record(tmp_path / f"a{i}.csv", i, amp) for i, amp in ((1, 0.3), (2, 1.0))]
    cli = piezo_cli("fit", "--model", model, *extra, "--quiet",
                    *sum((["--train", p] for p in train), []), "--out", tmp_path / "cli")
    assert cli.returncode == 0, cli.stderr
    theirs = json.loads((tmp_path / "cli" / "fit.json").read_text())
    kw = dict(order=2, lm_iterations=20 if model == "lfr" else 60)
    if model == "lfr":
        kw.update(lfr_iterations=3, input_delay=1)
    f = piezo.fit(train, model, out=tmp_path / "py", **kw)
    assert f.model == model
    mine, cli_model = _model(f.report), _model(theirs)
    assert mine.keys() == cli_model.keys()
    assert mine.get("extensions") == cli_model.get("extensions")
    if model == "lfr":
        assert mine["extensions"]["delay_samples"] == 1
    # (The fits sum over records in parallel: equal to rounding, not bit for bit.)
    r = f.report["report"]["train_rms_linear"]
    assert abs(r - theirs["report"]["train_rms_linear"]) <= 1e-6 * r
    v = _record(tmp_path / "v.csv", 3, 0.6)
    y = f.predict(v).y
    want = piezo.predict(tmp_path / "cli" / "fit.json", v).y
    assert np.allclose(y, want, rtol=0, atol=1e-6 * np.sqrt(np.mean(want ** 2)))
    assert (tmp_path / "py" / "fit.json").is_file()


def test_a_state_space_fit_refuses_what_it_cannot_use(tmp_path):
    a = _record(tmp_path / "a.csv", 1, 0.5)
    with pytest.raises(piezo.InputError, match="valid=, split= and linear_train="):
        piezo.fit([a], "ss", split=0.5)
    with pytest.raises(piezo.InputError, match="--order `0`"):
        piezo.fit([a], "ss", order=0)
    with pytest.raises(piezo.InputError, match="--lfr-linear `highest`"):
        piezo.fit([a], "lfr", lfr_linear="highest")
