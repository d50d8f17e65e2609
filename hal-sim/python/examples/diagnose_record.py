"""Fit a measured record and print what the classical Bouc-Wen model misses on it.

    pip install ./hal-sim/python
    python hal-sim/python/examples/diagnose_record.py [RECORD.csv]

Without an argument: the piezo actuator of `shared/data/smarthysteresis-piezo` (150 V, 1 Hz,
5 kHz), found through $PIEZO_DATA or beside the repository.
"""
import os
import pathlib
import sys

import piezo

repo = pathlib.Path(__file__).resolve().parents[3]
data = pathlib.Path(os.environ.get("PIEZO_DATA", repo.parent / "shared" / "data"))
path = sys.argv[1] if len(sys.argv) > 1 else data / "smarthysteresis-piezo" / "piezo_150V_1Hz.csv"

record = piezo.read_record(path)
print(f"{path}: {len(record)} samples at {record.sample_rate_hz:.0f} Hz, "
      f"{record.u.shape[0]} input(s), {record.y.shape[0]} output(s)")

# The classical Bouc-Wen model on the first half, scored on the second.
fit = piezo.fit(record, "cbw", split=0.5)
print(f"cbw: train RMSE {fit.train_rmse[0]:.4f} um, valid RMSE {fit.valid_rmse[0]:.4f} um")
print("  " + ", ".join(f"{k} = {v:.4g}" for k, v in fit.params.items()))
fit.save("diagnose_record_out")  # diagnose_record_out/fit.json: `piezo predict --model` reads it

# What it misses: the cause, its gain on the held-out half, the evidence.
d = piezo.diagnose(record)
print(d)
print(f"cause: {d.cause}, gain {100 * d.gain:.1f} %")
