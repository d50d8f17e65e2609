"""piezo.client: the controller's command protocol (src/command.rs) from Python.

A lab script talks to the firmware (the Nucleo's ST-LINK serial port, or the QEMU board's
UART on TCP) with `Piezo`; a refused command raises the exception of its numbered error
(`OutOfRange` for `err 8`, ...), and the recorder comes back as a NumPy array, read over the
framed binary transfer (`rec bin`: COBS packets, each checked by its CRC-32; a damaged packet
is asked for again, never taken as data) or, with `binary=False`, as text (`rec read`).

    from piezo.client import Piezo, OutOfRange
    with Piezo(port="/dev/ttyACM0") as p:          # or Piezo(tcp="127.0.0.1:4000")
        p.mode("ff+hgo-robust", ff="ims-cbw")
        p.command("wave sine 5 100 10")            # 5 um, 100 Hz, around 10 um
        data = p.record(["ref_um", "y_um", "u_volts"])   # (1024, 3) array
        try:
            p.set("slew", 0)
        except OutOfRange as e:
            print(e)                               # `set slew 0`: err 8 value out of range

Needs numpy; pyserial for a serial port (not for TCP).
"""
import socket
import struct
import time
import zlib

import numpy as np

# The firmware's numbered errors (`piezo_core::command::Error`); the CI test checks this
# table against src/command/error.rs.
ERRORS = {
    1: "LineTooLong", 2: "NotAscii", 3: "UnknownCommand", 4: "MissingArgument",
    5: "TooManyArguments", 6: "BadNumber", 7: "UnknownParam", 8: "OutOfRange",
    9: "UnknownMode", 10: "UnknownSignal", 11: "BadKeyword", 12: "Busy",
    13: "Unsupported", 14: "TooManyDigits", 15: "NoSettings", 16: "BadSettings",
    17: "Flash", 18: "OverBudget",
}


class PiezoError(Exception):
    """A command the firmware refused: `code`, `message` and the `command` line."""

    def __init__(self, command, code, message):
        super().__init__(f"`{command}`: err {code} {message}")
        self.command, self.code, self.message = command, code, message


# One exception class per error, named as in the firmware (`OutOfRange`, `Busy`, ...).
ERROR_CLASSES = {code: type(name, (PiezoError,), {}) for code, name in ERRORS.items()}
globals().update({cls.__name__: cls for cls in ERROR_CLASSES.values()})


class LinkError(Exception):
    """No reply within the timeout, or a line that is neither a reply nor data."""


# `rec bin` packets (src/bulk.rs): before COBS framing, start (u32 LE), count (u8),
# channels (u8), format (u16 LE, 1 = f32 LE), count x channels f32 LE, CRC-32 of all before.
FRAMES_PER_PACKET = 32
MAX_CHANNELS = 4
FORMAT_F32 = 1
# Requests of the same damaged frames before a transfer fails (as the Rust client).
MAX_ROUNDS = 8


def cobs_decode(framed):
    """The bytes of one COBS-framed packet (its zero delimiter removed); None for a zero
    byte inside or a block running past the end (as src/bulk.rs `cobs_decode`)."""
    out, i = bytearray(), 0
    while i < len(framed):
        code = framed[i]
        block = framed[i + 1:i + code]
        if code == 0 or len(block) != code - 1 or 0 in block:
            return None
        out += block
        i += code
        if code != 0xFF and i < len(framed):
            out.append(0)
    return bytes(out)


def decode_packet(framed):
    """A checked packet: (start, array count x channels of float32); None when its framing,
    length, checksum or header is wrong (damaged on the way)."""
    p = cobs_decode(framed)
    if p is None or len(p) < 12:
        return None
    body, crc = p[:-4], struct.unpack("<I", p[-4:])[0]
    if zlib.crc32(body) != crc:
        return None
    start, count, channels, fmt = struct.unpack("<IBBH", body[:8])
    if fmt != FORMAT_F32 or not 0 < count <= FRAMES_PER_PACKET or not 0 < channels <= MAX_CHANNELS:
        return None
    if len(body) - 8 != count * channels * 4:
        return None
    return start, np.frombuffer(body[8:], dtype="<f4").reshape(count, channels)


class Piezo:
    """One connection: `port` (serial, 115200 Bd) or `tcp` ("host:port")."""

    def __init__(self, port=None, tcp=None, baud=115200, timeout=5.0):
        if (port is None) == (tcp is None):
            raise ValueError("give one of port= or tcp=")
        self.timeout = timeout
        self._buf = b""
        if tcp is not None:
            host, p = tcp.rsplit(":", 1)
            self._sock = socket.create_connection((host, int(p)), timeout=timeout)
            self._serial = None
        else:
            import serial  # pyserial

            self._serial = serial.Serial(port, baud, timeout=timeout)
            self._sock = None
        self.command("ping")

    def close(self):
        (self._sock or self._serial).close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def _send(self, line):
        data = (line + "\n").encode("ascii")
        if self._sock:
            self._sock.sendall(data)
        else:
            self._serial.write(data)

    def _take(self, end, what):
        """Received bytes up to the next `end` byte (dropped), within the timeout."""
        deadline = time.monotonic() + self.timeout
        while end not in self._buf:
            if time.monotonic() > deadline:
                raise LinkError(f"no {what} within {self.timeout} s")
            self._recv()
        part, self._buf = self._buf.split(end, 1)
        return part

    def _line(self):
        return self._take(b"\n", "reply").decode("ascii", "replace").strip()

    def command(self, line, data=None):
        """Sends `line`, returns its `ok ...` reply (data lines before it go to `data`, a
        list, if given); an `err <code> <message>` reply raises its exception."""
        self._send(line)
        while True:
            r = self._line()
            if r.startswith("ok"):
                return r
            if r.startswith("err "):
                code, _, message = r[4:].partition(" ")
                cls = ERROR_CLASSES.get(int(code), PiezoError)
                raise cls(line, int(code), message)
            if data is not None and r:
                data.append(r)
            elif r and r != "ready":
                # Stale output (a boot banner): skipped.
                continue

    def get(self, name):
        """A parameter's value (`get <name>`: `ok <name> <value>`)."""
        return float(self.command(f"get {name}").split()[-1])

    def set(self, name, value):
        """Sets a parameter; returns the value the firmware took."""
        return float(self.command(f"set {name} {value}").split()[-1])

    def mode(self, law, ff=None):
        if ff is not None:
            self.command(f"ff {ff}")
        return self.command(f"mode {law}")

    def _packet(self):
        """Bytes up to the next zero delimiter (a COBS packet without it)."""
        return self._take(b"\0", "packet")

    def _recv(self):
        if self._sock and hasattr(socket, "TCP_QUICKACK"):
            # As the Rust client (serial/link.rs): no 40 ms delayed ACK against a peer that
            # writes byte by byte with Nagle on (QEMU's UART socket); not sticky, so per read.
            self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_QUICKACK, 1)
        chunk = self._sock.recv(4096) if self._sock else self._serial.read(256)
        if self._sock and not chunk:
            raise LinkError("the connection closed")
        self._buf += chunk

    def _drain(self):
        """After damage: drop what still arrives of the broken transfer (until 0.2 s of
        quiet), then get in step again (`ping`)."""
        link = self._sock or self._serial
        old = link.gettimeout() if self._sock else link.timeout
        try:
            if self._sock:
                self._sock.settimeout(0.2)
            else:
                self._serial.timeout = 0.2
            while True:
                try:
                    chunk = self._sock.recv(4096) if self._sock else self._serial.read(4096)
                except socket.timeout:
                    break
                if not chunk:
                    break
        finally:
            if self._sock:
                self._sock.settimeout(old)
            else:
                self._serial.timeout = old
        self._buf = b""
        self.command("ping")

    def capture(self, signals, poll_s=0.05, max_wait_s=600.0):
        """Captures one recorder buffer of `signals` (triggered at once); returns its frame
        count and the recorder's channels (the selected signals first: the firmware records
        all of its channels). Waits on the firmware's own progress (`rec status`), with
        `max_wait_s` of wall clock only for a dead link."""
        channels = self.command("rec sel " + " ".join(signals)).split()[3:]
        self.command("rec trig now")
        self.command("rec arm")
        deadline = time.monotonic() + max_wait_s
        while True:
            state = self.command("rec status").split()
            if state[2] == "done":
                return int(state[3]), channels
            if time.monotonic() > deadline:
                raise LinkError(f"recorder not done after {max_wait_s} s: {state}")
            time.sleep(poll_s)

    def read_recorder(self, n, channels, binary=True, request=4096):
        """Frames 0..n of a finished capture as an array (n x channels). Binary: damaged
        packets are counted in `self.damaged` and their frames asked for again (at most
        `MAX_ROUNDS` times, then `LinkError`). Values are the f32 the firmware recorded, as
        the float of their shortest decimal form, either way: `rec read` prints a decimal
        that reads back to the same f32 but is not always the shortest (up to 6 digits, or
        the shortest's count), so the text is read as that f32 first."""
        if not binary:
            rows = []
            for start in range(0, n, 64):
                lines = []
                self.command(f"rec read {start} {min(64, n - start)}", data=lines)
                rows += [[float(v) for v in l.split()[1:]] for l in lines]
            # Decimal -> f64 -> f32 rounds as decimal -> f32 here: the printed decimal lies
            # within a few units of its f32's last digit, far from any rounding midpoint.
            return np.array(rows, dtype=np.float32).astype(str).astype(np.float64)
        out = np.full((n, channels), np.nan, dtype=np.float32)
        have = np.zeros(n, dtype=bool)
        self.damaged = 0
        for _ in range(MAX_ROUNDS):
            missing = np.flatnonzero(~have)
            if missing.size == 0:
                break
            at = int(missing[0])
            while at < n:
                k = min(request, n - at)
                if not have[at:at + k].all() and not self._bin(at, k, channels, out, have):
                    self.damaged += 1
                    self._drain()
                at += k
        if not have.all():
            first = int(np.flatnonzero(~have)[0])
            raise LinkError(f"rec bin: frame {first} still damaged after {MAX_ROUNDS} requests")
        return out.astype(str).astype(np.float64)

    def _bin(self, at, k, channels, out, have):
        """One `rec bin at k`: True when its reply and every packet were whole (the frames
        of whole packets are kept either way)."""
        reply = self.command(f"rec bin {at} {k}").split()
        packets = -(-k // FRAMES_PER_PACKET)
        if reply[1:] != ["rec", "bin", str(k), str(packets)]:
            return False
        clean = True
        for _ in range(packets):
            got = decode_packet(self._packet())
            if got is None:
                clean = False
                continue
            start, frames = got
            if frames.shape[1] != channels or not at <= start <= start + len(frames) <= at + k:
                clean = False
                continue
            out[start:start + len(frames)] = frames
            have[start:start + len(frames)] = True
        return clean

    def record(self, signals, binary=True, poll_s=0.05, max_wait_s=600.0):
        """Captures one recorder buffer of `signals` and returns it (frames x the recorder's
        channels, the selected signals first), read as `read_recorder` does."""
        n, channels = self.capture(signals, poll_s, max_wait_s)
        return self.read_recorder(n, len(channels), binary)
