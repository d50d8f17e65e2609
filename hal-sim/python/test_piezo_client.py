"""The Python client against the QEMU firmware (issue 17 item 7): run by
.ci/test.d/38-python-client.sh with the QEMU board's UART on TCP:
`python3 test_piezo_client.py 127.0.0.1:<port>`. Fails (exit 1) on any mismatch."""
import pathlib
import re
import sys

import numpy as np

import piezo_client as pc


def errors_match_the_firmware():
    src = pathlib.Path(__file__).resolve().parents[2] / "src" / "command" / "error.rs"
    # The rows of the `errors!` table: `Variant = code => "message",`.
    rows = re.findall(r"^\s+(\w+) = (\d+) => \"", src.read_text(), re.M)
    codes = dict((int(c), n) for n, c in rows)
    assert codes == pc.ERRORS, f"client {pc.ERRORS} vs firmware {codes}"


def main(tcp):
    errors_match_the_firmware()
    with pc.Piezo(tcp=tcp, timeout=120.0) as p:
        assert p.get("u_max") == 150.0
        assert p.set("pid_kp", 0.75) == 0.75 and p.get("pid_kp") == 0.75
        try:
            p.set("slew", 0)
            raise AssertionError("slew 0 accepted")
        except pc.OutOfRange as e:
            assert e.code == 8 and "out of range" in e.message, e
        try:
            p.command("mode warp-drive")
            raise AssertionError("unknown mode accepted")
        except pc.UnknownMode as e:
            assert e.code == 9
        try:
            p.mode("nmpc")
            raise AssertionError("nmpc accepted at 100 kHz on the M4F")
        except pc.OverBudget:
            pass
        assert p.mode("ff+hgo-robust", ff="ims-cbw") == "ok mode ff+hgo-robust"
        assert p.command("wave sine 5 100 10").startswith("ok wave sine")
        data = p.record(["ref_um", "y_um", "u_volts", "error_um"])
        assert data.shape == (1024, 4), data.shape
        assert np.isfinite(data).all()
        ref, y, u = data[:, 0], data[:, 1], data[:, 2]
        assert 4.9 < ref.min() < 5.2 and 14.8 < ref.max() < 15.1, (ref.min(), ref.max())
        assert (0.0 <= u).all() and (u <= 150.0).all()
        # The stage follows the sine (right after the mode switch: the loop is still
        # settling, so the shape, not the error, is checked).
        rms = float(np.sqrt(np.mean((y - ref) ** 2)))
        corr = float(np.corrcoef(y, ref)[0, 1])
        assert corr > 0.9 and rms < 3.0, f"tracking rms {rms} um, correlation {corr}"
        print(f"python client: {len(pc.ERRORS)} error codes match, 1024 x 4 frames, "
              f"tracking rms {rms:.4f} um (correlation {corr:.4f}), ref {ref.min():.3f}..{ref.max():.3f} um")


if __name__ == "__main__":
    main(sys.argv[1])
