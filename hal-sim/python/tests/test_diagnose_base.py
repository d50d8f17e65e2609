"""diagnose(base=...): discovery from an identified state-space model, as `piezo diagnose
--base` gives it for the same records, with the extended model usable as a fit."""
import json

import numpy as np

import piezo

PERIOD, FS = 512, 1000.0


def _record(path, seed):
    """Two steady periods of a random-phase multisine through a first-order plant whose
    input arrives three samples late (`t,u1,y1`)."""
    rng = np.random.default_rng(seed)
    k = np.arange(PERIOD)
    one = sum(np.cos(2 * np.pi * l * k / PERIOD + rng.uniform(0, 2 * np.pi))
              for l in range(1, 60)) / 6.0
    u = np.tile(one, 3)
    y = np.zeros_like(u)
    for i in range(1, len(u)):
        y[i] = 0.8 * y[i - 1] + 0.5 * (u[i - 4] if i >= 4 else 0.0)
    u, y = u[PERIOD:], y[PERIOD:]
    t = np.arange(len(u)) / FS
    np.savetxt(path, np.column_stack([t, u, y]), delimiter=",", header="t,u1,y1",
               comments="", fmt="%.12g")
    return path


def test_base_names_the_delay_as_the_cli_does(tmp_path, piezo_cli):
    train = [_record(tmp_path / f"a{i}.csv", i) for i in (1, 2)]
    valid = _record(tmp_path / "b.csv", 3)
    fit = piezo_cli("fit", "--model", "ss", "--order", "1", "--quiet",
                    *sum((["--train", p] for p in train), []), "--out", tmp_path / "base")
    assert fit.returncode == 0, fit.stderr
    base = tmp_path / "base" / "fit.json"
    d = piezo.diagnose(train, valid, base=base)
    assert isinstance(d, piezo.BaseDiagnosis)
    assert d.named == ["delay"], d.summary
    assert d.gain > 0.5, d.summary
    cli = piezo_cli("diagnose", "--base", base, *sum((["--train", p] for p in train), []),
                    "--valid", valid, "--json", "--out", tmp_path / "cli")
    assert cli.returncode == 0, cli.stderr
    j = json.loads(cli.stdout)
    assert j["named"] == d.named
    assert abs(j["final_valid"] - d.report["final_valid"]) <= 1e-9 * j["final_valid"]
    # The extended model predicts like the CLI's saved one.
    mine = d.fit.predict(valid).y
    theirs = piezo.predict(tmp_path / "cli" / "fit.json", valid).y
    assert np.allclose(mine, theirs, rtol=0, atol=1e-9)
    # Three samples late with no direct term, or four with one: both are exact.
    assert d.fit.report["extensions"]["delay_samples"] in (3, 4)


def test_a_per_axis_fit_is_refused_as_a_base(tmp_path, backlash):
    f = piezo.fit(backlash, "cbw", split=0.5, generations=20, lm_iterations=5)
    try:
        piezo.diagnose(backlash, backlash, base=f)
    except piezo.InputError as e:
        assert "base= takes a state-space fit.json" in str(e)
    else:
        raise AssertionError("a cbw fit was taken as a base")
