"""The Python client (`piezo.client`) against the QEMU firmware: run by
.ci/test.d/38-python-client.sh with the QEMU board's UART on TCP,
`PYTHONPATH=hal-sim/python/python python3 hal-sim/python/tests/client_on_qemu.py
127.0.0.1:<port>` (the client needs no build; pytest does not collect this file). Fails
(exit 1) on any mismatch."""
import pathlib
import re
import struct
import sys
import time
import zlib

import numpy as np

import piezo.client as pc


def errors_match_the_firmware():
    src = pathlib.Path(__file__).resolve().parents[3] / "src" / "command" / "error.rs"
    # The rows of the `errors!` table: `Variant = code => "message",`.
    rows = re.findall(r"^\s+(\w+) = (\d+) => \"", src.read_text(), re.M)
    codes = dict((int(c), n) for n, c in rows)
    assert codes == pc.ERRORS, f"client {pc.ERRORS} vs firmware {codes}"


def cobs_encode(data):
    """The test's own COBS encoder (the firmware's is src/bulk.rs)."""
    out, block = bytearray(), bytearray()
    for b in data:
        if b == 0:
            out += bytes([len(block) + 1]) + block
            block = bytearray()
        else:
            block.append(b)
            if len(block) == 0xFE:
                out += b"\xff" + block
                block = bytearray()
    return bytes(out + bytes([len(block) + 1]) + block)


def damaged_packets_are_refused():
    """A packet as the firmware frames it decodes; every single-byte change of it is
    refused (framing, length, checksum or header), never read as other data."""
    frames = np.arange(32 * 4, dtype="<f4").reshape(32, 4) - 7.5
    body = struct.pack("<IBBH", 96, 32, 4, 1) + frames.tobytes()
    framed = cobs_encode(body + struct.pack("<I", zlib.crc32(body)))
    start, got = pc.decode_packet(framed)
    assert start == 96 and np.array_equal(got, frames)
    for i in range(len(framed)):
        for flip in (0x01, 0x80, 0xFF):
            bad = bytearray(framed)
            bad[i] ^= flip
            if 0 in bad:
                continue  # a zero ends the packet on the link: the reader splits there
            assert pc.decode_packet(bytes(bad)) is None, (i, flip)
    assert pc.decode_packet(framed[:-1]) is None and pc.decode_packet(b"") is None


def main(tcp):
    errors_match_the_firmware()
    damaged_packets_are_refused()
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
        # NMPC fits 100 kHz on the M4F with its solve in the solver task.
        assert p.mode("nmpc") == "ok mode nmpc"
        assert p.mode("ff+hgo-robust", ff="ims-cbw") == "ok mode ff+hgo-robust"
        assert p.command("wave sine 5 100 10").startswith("ok wave sine")
        signals = ["ref_um", "y_um", "u_volts", "error_um"]
        n, channels = p.capture(signals)
        assert channels == signals, channels
        t0 = time.monotonic()
        data = p.read_recorder(n, 4)
        rate = n / (time.monotonic() - t0)
        assert data.shape == (1024, 4), data.shape
        assert p.damaged == 0, p.damaged
        # The same capture as text: the same values.
        text = p.read_recorder(n, 4, binary=False)
        assert np.array_equal(text, data), np.argwhere(text != data)[:5]
        # A packet damaged on the way is refused and asked for again.
        packet, hits = p._packet, []

        def damage_once():
            b = bytearray(packet())
            if not hits:
                hits.append(1)
                b[len(b) // 2] ^= 0x40 if b[len(b) // 2] != 0x40 else 0x01
            return bytes(b)

        p._packet = damage_once
        again = p.read_recorder(n, 4)
        p._packet = packet
        assert p.damaged == 1 and np.array_equal(again, data), p.damaged
        assert np.isfinite(data).all()
        ref, y, u = data[:, 0], data[:, 1], data[:, 2]
        assert 4.9 < ref.min() < 5.2 and 14.8 < ref.max() < 15.1, (ref.min(), ref.max())
        assert (0.0 <= u).all() and (u <= 150.0).all()
        # The stage follows the sine (right after the mode switch: the loop is still
        # settling, so the shape, not the error, is checked).
        rms = float(np.sqrt(np.mean((y - ref) ** 2)))
        corr = float(np.corrcoef(y, ref)[0, 1])
        assert corr > 0.9 and rms < 3.0, f"tracking rms {rms} um, correlation {corr}"
        print(f"python client: {len(pc.ERRORS)} error codes match, 1024 x 4 frames over rec bin "
              f"({rate:.0f} frames/s on QEMU's TCP UART; equal to rec read; a damaged packet "
              f"asked for again), "
              f"tracking rms {rms:.4f} um (correlation {corr:.4f}), ref {ref.min():.3f}..{ref.max():.3f} um")


if __name__ == "__main__":
    main(sys.argv[1])
