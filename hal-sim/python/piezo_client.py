"""piezo_client: the controller's command protocol (src/command.rs) from Python.

A lab script talks to the firmware (the Nucleo's ST-LINK serial port, or the QEMU board's
UART on TCP) with `Piezo`; a refused command raises the exception of its numbered error
(`OutOfRange` for `err 8`, ...), and the recorder comes back as a NumPy array.

    from piezo_client import Piezo, OutOfRange
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
import time

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

    def _line(self):
        deadline = time.monotonic() + self.timeout
        while b"\n" not in self._buf:
            if time.monotonic() > deadline:
                raise LinkError(f"no reply within {self.timeout} s")
            chunk = self._sock.recv(4096) if self._sock else self._serial.read(256)
            if self._sock and not chunk:
                raise LinkError("the connection closed")
            self._buf += chunk
        line, self._buf = self._buf.split(b"\n", 1)
        return line.decode("ascii", "replace").strip()

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

    def record(self, signals, poll_s=0.05, max_wait_s=600.0):
        """Captures one recorder buffer of `signals` (triggered at once) and returns it as
        an array (frames x signals). Waits on the firmware's own progress (`rec status`),
        with `max_wait_s` of wall clock only for a dead link."""
        self.command("rec sel " + " ".join(signals))
        self.command("rec trig now")
        self.command("rec arm")
        deadline = time.monotonic() + max_wait_s
        while True:
            state = self.command("rec status").split()
            if state[2] == "done":
                n = int(state[3])
                break
            if time.monotonic() > deadline:
                raise LinkError(f"recorder not done after {max_wait_s} s: {state}")
            time.sleep(poll_s)
        rows = []
        for start in range(0, n, 64):
            lines = []
            self.command(f"rec read {start} {min(64, n - start)}", data=lines)
            rows += [[float(v) for v in l.split()[1:]] for l in lines]
        return np.array(rows)
