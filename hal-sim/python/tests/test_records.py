"""Records: paths and arrays, the CLI's reading rules, errors as exceptions with the CLI's
messages."""
import numpy as np
import pytest

import piezo


def test_reads_a_measured_record(backlash):
    r = piezo.read_record(backlash)
    assert r.u.shape == (1, 8027) and r.y.shape == (1, 8027)
    assert r.sample_rate_hz == pytest.approx(200.0, rel=1e-6)
    # `t,u,y` names no unit: read in s, V, um, and said so.
    assert "no unit" in r.unit_note
    assert r.name == str(backlash)


def test_units_in_the_header_are_converted(tmp_path):
    p = tmp_path / "r.csv"
    p.write_text("t_ms,u_mV,y_nm\n0,1500,2500\n1,1600,2600\n2,1700,2700\n")
    r = piezo.read_record(p)
    np.testing.assert_allclose(r.t, [0, 1e-3, 2e-3])
    np.testing.assert_allclose(r.u[0], [1.5, 1.6, 1.7])
    np.testing.assert_allclose(r.y[0], [2.5, 2.6, 2.7])
    assert r.unit_note is None


def test_arrays_of_either_orientation():
    t = np.arange(100) * 1e-3
    u = np.stack([np.sin(t), np.cos(t)])
    y = 2 * u
    a = piezo.as_record((t, u, y))
    b = piezo.as_record((t, u.T, y.T))
    assert a.u.shape == (2, 100) and a.y.shape == (2, 100)
    np.testing.assert_array_equal(a.u, b.u)
    one = piezo.as_record((t, u[0], y[0]))
    assert one.u.shape == (1, 100)


def test_bad_arrays_raise_value_errors():
    t = np.arange(10.0)
    with pytest.raises(piezo.InputError, match=r"u has shape \(9,\)"):
        piezo.as_record((t, np.zeros(9), np.zeros(10)))
    with pytest.raises(ValueError, match="orientation is ambiguous"):
        piezo.as_record((t, np.zeros((10, 10)), np.zeros(10)))


def test_missing_file_is_an_os_error(tmp_path):
    p = tmp_path / "none.csv"
    with pytest.raises(OSError, match=f"cannot read record {p}: No such file") as e:
        piezo.read_record(p)
    assert isinstance(e.value, piezo.FileError)


def test_errors_carry_the_cli_message(tmp_path, piezo_cli):
    """The same bad record through the package and through `piezo fit`: one message."""
    p = tmp_path / "bad.csv"
    p.write_text("t_s,u_V,y [ft]\n0,1,2\n0.1,1,2\n")
    with pytest.raises(piezo.InputError) as e:
        piezo.fit(p, "cbw")
    cli = piezo_cli("fit", "--model", "cbw", "--train", p, "--quiet")
    assert cli.returncode == 1
    assert cli.stderr.strip().splitlines()[-1] == f"error: {e.value}"
    assert "unknown length unit" in str(e.value)


def test_non_finite_samples_are_refused():
    t = np.arange(100) * 1e-3
    u = np.sin(t)
    y = u.copy()
    y[7] = np.nan
    with pytest.raises(piezo.InputError, match="column `y` sample 7 is not finite"):
        piezo.fit((t, u, y), "cbw")
