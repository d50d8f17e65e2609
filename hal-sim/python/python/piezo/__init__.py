"""piezo: identify, predict and diagnose piezo stages from Python, and talk to the firmware.

    import piezo
    fit = piezo.fit("model_1Hz.csv", "cbw", split=0.5)     # or arrays (t, u, y)
    fit.save("out")                                        # out/fit.json, as `piezo fit --out`
    print(piezo.predict("out/fit.json", "test.csv").rmse_mean)
    print(piezo.diagnose("piezo_150V_1Hz.csv"))            # the cause, its gain, the evidence

`fit`, `predict` and `diagnose` are the `piezo` CLI's commands on NumPy arrays or CSV
records, run by the same library (`piezo-ident`); errors are `piezo.errors.InputError`
(a `ValueError`) or `FileError` (an `OSError`) with the CLI's messages. `piezo.client` is
the serial client of the firmware (`from piezo.client import Piezo`).
"""
from . import errors
from .errors import FileError, InputError, PiezoIdentError
from .ident import (
    STATE_SPACE,
    BaseDiagnosis,
    Diagnosis,
    FitResult,
    Prediction,
    Record,
    as_record,
    diagnose,
    fit,
    models,
    predict,
    read_record,
)

__all__ = [
    "STATE_SPACE", "BaseDiagnosis", "Diagnosis", "FileError", "FitResult", "InputError", "PiezoIdentError", "Prediction",
    "Record", "as_record", "diagnose", "errors", "fit", "models", "predict", "read_record",
]
