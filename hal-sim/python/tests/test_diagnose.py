"""diagnose: the package's answer is `piezo diagnose --json`'s for the same record."""
import json

import numpy as np
import pytest

import piezo


def test_matches_the_cli_json(backlash, piezo_cli):
    d = piezo.diagnose(backlash)
    cli = piezo_cli("diagnose", "--train", backlash, "--json")
    assert cli.returncode == 0, cli.stderr
    assert d.report == json.loads(cli.stdout)
    assert d.cause == d.report["cause"] and d.causes == d.report["causes"]
    assert d.base["model"] and d.extended["rmse_valid"] <= d.base["rmse_valid"]
    assert "samples 0..4013 of" in d.report["split"]


def test_summary_is_the_cli_text(backlash, piezo_cli):
    d = piezo.diagnose(backlash, split=0.6)
    cli = piezo_cli("diagnose", "--train", backlash, "--split", 0.6)
    assert cli.returncode == 0, cli.stderr
    assert str(d) == cli.stdout
    assert d.summary.startswith("split: no --valid: samples 0..4816 of")


def test_arrays_and_several_records(backlash):
    r = piezo.read_record(backlash)
    a, b = r.slice(0, 4000), r.slice(4000, 8000)
    d = piezo.diagnose([(a.t, a.u, a.y)], [(b.t - b.t[0], b.u, b.y)])
    assert "split" not in d.report
    assert isinstance(d.gain, float) and np.isfinite(d.gain)
    assert d.report["plots"] == []


def test_too_short_a_record_is_refused():
    t = np.arange(20) * 1e-3
    with pytest.raises(piezo.InputError, match="record <arrays>: record has 20 samples, at least 50 needed"):
        piezo.diagnose((t, np.sin(t), np.sin(t)))
