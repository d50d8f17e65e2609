#!/usr/bin/env python3
"""Writes the QEMU command flood (issue 15 item 3) to stdout: every command of the protocol,
law rebuilds and `rec read` included, ROUNDS times, framed by the harness lines
`flood start` / `flood stop`, during closed-loop control (ff+hgo-robust on IMS-CBW)."""
import sys

ROUNDS = int(sys.argv[1]) if len(sys.argv) > 1 else 3
# Laws the flood selects, every one the M4F's budget takes at 100 kHz: nmpc and ff+nmpc
# with their solve in the priority-2 solver task (its lock delays the control task too).
LAWS = ["open-loop", "pid", "ff+pid", "hgo-robust", "ff+hgo-robust", "fts", "ff+fts",
        "adrc", "ff+adrc", "nmpc", "ff+nmpc"]
FFS = ["linear", "ims-cbw-delayed", "ims-cbw"]
PARAMS = ["u_min", "u_max", "slew", "um_per_code", "volts_per_code", "sample_hz", "cbw_d",
          "cbw_alpha", "cbw_beta", "cbw_gamma", "um_per_volt", "offset_um", "hgo_eps",
          "lambda1", "lambda2", "pid_kp", "pid_ki"]
# Model and gain values as the firmware starts with them (each `set` rebuilds the law and
# the compensator), and the limits.
SETS = [("u_min", "0"), ("u_max", "150"), ("slew", "1000000"), ("cbw_d", "0.16"),
        ("cbw_alpha", "0.07"), ("cbw_beta", "0.02"), ("cbw_gamma", "0.01"),
        ("um_per_volt", "0.16"), ("offset_um", "0"), ("hgo_eps", "0.0002"),
        ("lambda1", "2000"), ("lambda2", "2000"), ("pid_kp", "0.5"), ("pid_ki", "2000"),
        ("slew", "0")]  # the last one is refused (err 8)


def round_():
    out = ["ping", "help"]
    out += [f"get {p}" for p in PARAMS]
    out += [f"set {p} {v}" for p, v in SETS]
    out += ["cbw 0.16 0.07 0.02 0.01", "defaults"]
    for law in LAWS:
        out += [f"mode {law}", "rec read 0 8"]
    out += ["mode ff+hgo-robust"]
    out += [f"ff {f}" for f in FFS]
    out += ["wave hold 10", "wave triangle 5 50 10", "wave square 2 20 10",
            "wave steps 5 15 4 50", "table clear", "table add 8 10 12 10", "table len",
            "wave table 100", "axis", "axis 0", "wave sine 5 100 10", "stats", "rec div",
            "rec status", "rec read 0 64", "rec read 960 64", "fault", "fault clear",
            "bench", "selftest", "wave off", "wave sine 5 100 10", "nonsense",
            "get nothing"]
    return out


# The recorder captures 1024 periods from the start; the harness line `wait 1100` holds
# the input for 1100 control periods (virtual time, whatever the host's speed), so every
# round's `rec read` streams its frames.
lines = ["mode ff+hgo-robust", "ff ims-cbw", "wave sine 5 100 10",
         "rec sel ref_um y_um u_volts error_um", "rec div 1", "rec trig now", "rec arm",
         "wait 1100", "flood start"]
for _ in range(ROUNDS):
    lines += round_()
lines += ["rec sel ref_um y_um u_volts error_um", "rec trig now", "rec arm", "rec stop"]
lines += ["flood stop", "exit"]
print("\n".join(lines))
