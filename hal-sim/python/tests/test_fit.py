"""fit -> fit.json -> predict, through the package and the CLI: the same model, the same
file, the same simulated output."""
import json
import re

import numpy as np
import pytest

import piezo

# A short global search: these tests check the plumbing, not the optimum.
QUICK = dict(generations=20, lm_iterations=20)


def without_seconds(v):
    if isinstance(v, dict):
        return {k: without_seconds(x) for k, x in v.items() if k != "seconds"}
    if isinstance(v, list):
        return [without_seconds(x) for x in v]
    return v


def test_models_are_listed():
    names = [n for n, _ in piezo.models()]
    assert "cbw" in names and "pi" in names


def test_fit_writes_the_cli_fit_json(backlash, tmp_path, piezo_cli):
    f = piezo.fit(backlash, "cbw", split=0.5, **QUICK)
    assert f.model == "cbw" and f.report["format"] == "piezo-fit/1"
    span = float(np.ptp(piezo.read_record(backlash).y))
    # A Bouc-Wen loop on a measured flexure: within a few percent of the output span.
    assert 0 < f.train_rmse[0] < 0.05 * span
    assert 0 < f.valid_rmse[0] < 0.1 * span
    saved = f.save(tmp_path / "py")
    assert saved == tmp_path / "py" / "fit.json"
    cli = piezo_cli("fit", "--model", "cbw", "--train", backlash, "--split", 0.5, "--quiet",
                    "--generations", 20, "--lm-iterations", 20, "--out", tmp_path / "cli")
    assert cli.returncode == 0, cli.stderr
    ours = json.loads(saved.read_text())
    theirs = json.loads((tmp_path / "cli" / "fit.json").read_text())
    # Everything but the run times (of the fit, of its global search) is the same, to the
    # last bit.
    assert without_seconds(ours) == without_seconds(theirs)
    assert "seconds" in ours and "seconds" in ours["parts"][0]["fit"]["search"]


def test_round_trip_through_piezo_predict(backlash, tmp_path, piezo_cli):
    f = piezo.fit(backlash, "cbw", **QUICK)
    path = f.save(tmp_path)
    out = tmp_path / "pred.csv"
    cli = piezo_cli("predict", "--model", path, "--input", backlash, "--out", out)
    assert cli.returncode == 0, cli.stderr
    rows = [line for line in out.read_text().splitlines() if not line.startswith("#")]
    assert rows[0] == "t,y"
    by_cli = np.loadtxt(rows[1:], delimiter=",")
    p = piezo.predict(path, backlash)
    # The CLI writes every digit: the same simulation, bit for bit.
    np.testing.assert_array_equal(by_cli[:, 1], p.y[0])
    # Without --valid the training record is simulated from rest, as predict does.
    np.testing.assert_allclose(p.y, f.train_sim, rtol=0, atol=1e-9)
    assert p.rmse_mean == pytest.approx(p.rmse_last_period[0])
    printed = re.search(r"last period of (\d+) samples: mean (\S+),", cli.stdout)
    assert int(printed[1]) == p.period_samples
    assert float(printed[2]) == pytest.approx(p.rmse_mean, rel=1e-5)
    # From the result itself, and on arrays without outputs.
    rec = piezo.read_record(backlash)
    q = f.predict((rec.t, rec.u))
    np.testing.assert_array_equal(q.y, p.y)
    assert q.rmse_mean is None


def test_multi_axis_arrays(data_dir):
    """Three actuators, three sensors (the fine steering mirror): one model per pair."""
    r = piezo.read_record(data_dir / "fsm-benchmark" / "fsm_300mV_r1.csv").slice(0, 3000)
    # (samples, channels) arrays, as a DataFrame's columns give them.
    f = piezo.fit((r.t, r.u.T, r.y.T), "pi", generations=10, lm_iterations=10)
    assert f.report["inputs"] == 3 and f.report["outputs"] == 3
    assert f.train_sim.shape == (3, 3000)
    kinds = {p["kind"] for p in f.parts}
    assert "direct" in kinds
    p = piezo.predict(f, r)
    assert p.y.shape == (3, 3000) and len(p.rmse_last_period) == 3


def test_predict_errors_carry_the_cli_message(backlash, tmp_path, piezo_cli, data_dir):
    f = piezo.fit(backlash, "pi", generations=5, lm_iterations=5)
    path = f.save(tmp_path)
    three = data_dir / "fsm-benchmark" / "fsm_100mV_r1.csv"
    with pytest.raises(piezo.InputError) as e:
        piezo.predict(path, three)
    cli = piezo_cli("predict", "--model", path, "--input", three)
    assert cli.returncode == 1
    assert cli.stderr.strip().splitlines()[-1] == f"error: {e.value}"
    assert "the model has 1 inputs, the record 3" in str(e.value)


def test_missing_model_is_an_os_error(backlash, tmp_path, piezo_cli):
    missing = tmp_path / "fit.json"
    with pytest.raises(OSError) as e:
        piezo.predict(missing, backlash)
    assert isinstance(e.value, piezo.FileError)
    cli = piezo_cli("predict", "--model", missing, "--input", backlash)
    assert cli.stderr.strip().splitlines()[-1] == f"error: {e.value}"
    assert str(e.value).startswith(f"cannot read {missing}: No such file")


def test_bad_options_are_value_errors(backlash):
    with pytest.raises(ValueError, match="unknown model `nope`"):
        piezo.fit(backlash, "nope")
    with pytest.raises(ValueError, match="--split must be within 0.1..0.9, got 0.95"):
        piezo.fit(backlash, "cbw", split=0.95)
    with pytest.raises(ValueError, match="valid=, split= and linear_train= apply to"):
        piezo.fit(backlash, "ss", split=0.5)
