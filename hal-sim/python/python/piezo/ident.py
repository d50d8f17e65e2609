"""Identification from Python: `fit`, `predict` and `diagnose` of the `piezo` CLI on NumPy
arrays or the project's CSV records, through the `piezo-ident` library (the same code the
CLI runs, so the answers are the CLI's).

Records are in s, V and um. A record is a path to a CSV file (read with the CLI's column
and unit rules), a `Record`, or arrays `(t, u, y)`: `t` of n samples, `u` and `y` one
channel as n values or several as an array of shape (channels, n) or (n, channels).
"""
from __future__ import annotations

import dataclasses
import json
import os
import pathlib
from typing import Any, Optional, Sequence, Union

import numpy as np

from .errors import InputError


def _lib():
    try:
        from . import _native
    except ImportError as e:  # a source checkout on sys.path, not an installed package
        raise ImportError(
            "the native part of `piezo` is not built: install the package with "
            "`pip install ./hal-sim/python`"
        ) from e
    return _native


@dataclasses.dataclass
class Record:
    """Time `t` (s, shape (n,)), inputs `u` (V, (inputs, n)), outputs `y` (um, (outputs,
    n); no rows for an input record). `name` is what reports call it (the path it was read
    from); `unit_note` says which columns stated no unit (read in s, V, um)."""

    t: np.ndarray
    u: np.ndarray
    y: np.ndarray
    name: str = "<arrays>"
    unit_note: Optional[str] = None
    comments: list = dataclasses.field(default_factory=list)
    extra: dict = dataclasses.field(default_factory=dict)

    def __len__(self):
        return len(self.t)

    @property
    def dt(self) -> float:
        """Mean sample period (s)."""
        return float((self.t[-1] - self.t[0]) / (len(self.t) - 1))

    @property
    def sample_rate_hz(self) -> float:
        return 1.0 / self.dt

    def slice(self, start: int, end: int) -> "Record":
        """Samples `start..end`."""
        return Record(self.t[start:end], self.u[:, start:end], self.y[:, start:end],
                      f"{self.name}[{start}:{end}]", self.unit_note, list(self.comments),
                      {k: v[start:end] for k, v in self.extra.items()})

    def _native(self):
        return (self.name, self.t, self.u, self.y)


RecordLike = Union[Record, str, os.PathLike, Sequence[Any], dict]


def read_record(path, *, t_col=None, u_col=(), y_col=(), input_unit="V", output_unit="um",
                outputs_optional=False) -> Record:
    """Reads a CSV record of the project's convention (`t_s,u_V,y_um`, several channels
    `u1..uk`, `y1..yn`; units in the header names, converted to s, V and um). The options
    are the CLI's `--t-col`, `--u-col`, `--y-col`, `--input-unit` and `--output-unit`."""
    if isinstance(u_col, str):
        u_col = [u_col]
    if isinstance(y_col, str):
        y_col = [y_col]
    name = os.fspath(path)
    d = _lib().read_record(name, t_col, list(u_col), list(y_col), input_unit, output_unit,
                           outputs_optional)
    return Record(d["t"], d["u"], d["y"], name, d["unit_note"], d["comments"], d["extra"])


def _channels(a, n: int, what: str) -> np.ndarray:
    """`a` as a C-contiguous float64 array of shape (channels, n)."""
    a = np.asarray(a, dtype=np.float64)
    given = a.shape
    if a.ndim == 1:
        a = a[np.newaxis, :]
    elif a.ndim == 2:
        rows, cols = a.shape
        if rows == n and cols != n:
            a = a.T
        elif rows == n and cols == n and n > 1:
            raise InputError(f"{what} has shape {a.shape}: with as many channels as samples "
                             f"the orientation is ambiguous; give (channels, samples)")
    else:
        raise InputError(f"{what} has {a.ndim} dimensions; expected 1 or 2")
    if a.shape[1] != n:
        raise InputError(f"{what} has shape {given}; t has {n} samples")
    return np.ascontiguousarray(a)


def as_record(data: RecordLike, *, outputs_optional=False, columns=None) -> Record:
    """A `Record` from a path (read with `columns`, the keywords of `read_record`), a
    `Record`, a dict with `t`, `u` (and `y`), or a tuple `(t, u, y)` (`(t, u)` for input
    records)."""
    if isinstance(data, Record):
        return data
    if isinstance(data, (str, os.PathLike)):
        return read_record(data, outputs_optional=outputs_optional, **(columns or {}))
    if isinstance(data, dict):
        data = (data["t"], data["u"], data.get("y"))
    if not isinstance(data, (tuple, list)) or len(data) not in (2, 3):
        raise InputError("a record is a path, a Record, a dict or a tuple (t, u, y)")
    t = np.ascontiguousarray(np.asarray(data[0], dtype=np.float64))
    if t.ndim != 1:
        raise InputError(f"t has shape {t.shape}; expected one dimension")
    n = len(t)
    u = _channels(data[1], n, "u")
    y = data[2] if len(data) == 3 else None
    if y is None:
        if not outputs_optional:
            raise InputError("a record needs at least one input and one output channel")
        y = np.zeros((0, n))
    else:
        y = _channels(y, n, "y")
    return Record(t, u, y)


def models() -> list:
    """The models `fit` knows, `(name, description)`, as `piezo fit --list`."""
    return list(_lib().models_list())


@dataclasses.dataclass
class FitResult:
    """What `fit` identified. `fit_json` is the text `piezo fit --out DIR` writes to
    `DIR/fit.json` (`save` writes it; `piezo predict --model` and `piezo.predict` load it);
    `report` is the same as a dict. Simulated outputs `train_sim`, `valid_sim` (um,
    (outputs, n)) are those the metrics score."""

    fit_json: str
    report: dict
    train_sim: np.ndarray
    valid_sim: Optional[np.ndarray] = None
    valid_rest_sim: Optional[np.ndarray] = None

    @property
    def model(self) -> str:
        return self.report["model"]

    @property
    def parts(self) -> list:
        """The identified channel pairs, each with its fitted parameters."""
        return self.report["parts"]

    @property
    def params(self) -> dict:
        """Parameters of a single-channel fit by name (`{}` for several parts)."""
        if len(self.parts) != 1:
            return {}
        return {name: value for name, value in self.parts[0]["fit"]["params"]}

    @property
    def train_rmse(self) -> list:
        """RMSE (um) per output on the training record."""
        return [m["metrics"]["rmse"] for m in self.report["train_metrics"]]

    @property
    def valid_rmse(self) -> list:
        """RMSE (um) per output on the validation samples (empty without validation)."""
        return [m["metrics"]["rmse"] for m in self.report["valid_metrics"]]

    def save(self, path) -> pathlib.Path:
        """Writes `fit.json`: into `path` if it is a folder or has no `.json` suffix (as
        `piezo fit --out`), else to `path`. Returns the file written."""
        p = pathlib.Path(path)
        if p.suffix != ".json" or p.is_dir():
            p = p / "fit.json"
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(self.fit_json)
        return p

    def predict(self, input: RecordLike, **kw) -> "Prediction":
        """`predict(self, input)`."""
        return predict(self, input, **kw)


STATE_SPACE = ("ss", "hammerstein-ss", "scheduled-ss", "lfr")


def fit(train, model: str = "cbw", *, valid: Optional[RecordLike] = None,
        split: Optional[float] = None, valid_periodic: int = 0, linear: int = 0,
        linear_train: Optional[RecordLike] = None, optimizer: str = "de",
        generations: int = 300, population: int = 0, seed: int = 1,
        lm_iterations: int = 60, upsample: int = 20, progress: bool = False,
        out=None, columns: Optional[dict] = None, order=None, hysteresis: str = "cbw",
        joint_iterations: int = 30, schedule_tau_s: float = 0.15,
        lfr_basis=None, lfr_linear: Optional[str] = None,
        lfr_channels: str = "outputs:2", lfr_iterations: int = 30,
        lfr_guard: Optional[float] = None, input_delay: int = 0) -> FitResult:
    """`piezo fit --model MODEL --train TRAIN [--valid VALID | --split F] ...`: identifies
    `model` (`models()` lists them) on `train`, scores it there and on the validation
    samples. The keywords are the CLI's options; `out` writes `fit.json` into that folder.

    The state-space models (`ss`, `hammerstein-ss`, `scheduled-ss`, `lfr`: `STATE_SPACE`)
    fit one multivariable model to `train`, a record or a list of them (periodic records
    for `lfr` and `scheduled-ss`), with the CLI's `order` (a number or `"auto"`; default
    32 for `lfr`, else auto), `hysteresis`, `lm_iterations`, `joint_iterations`,
    `schedule_tau_s`, `lfr_basis` (`None`: the CLI's default), `lfr_linear`,
    `lfr_channels`, `lfr_iterations`, `lfr_guard` and `input_delay`; the answer's
    `report` is the `fit.json` (`report["report"]` its training errors) and it has no
    simulated records: score it with `predict`."""
    lib = _lib()
    rec = lambda r: as_record(r, columns=columns)._native()  # noqa: E731
    if model in STATE_SPACE:
        if valid is not None or split is not None or linear_train is not None:
            raise InputError(f"model `{model}`: valid=, split= and linear_train= apply to "
                             "the per-axis models; score a state-space fit with predict()")
        text = lib.fit_ss([rec(r) for r in _records(train)], model,
                          None if order is None else str(order), hysteresis, lm_iterations,
                          joint_iterations, schedule_tau_s,
                          None if lfr_basis is None else list(lfr_basis), lfr_linear,
                          lfr_channels, lfr_iterations, lfr_guard, input_delay, progress)
        r = FitResult(text, json.loads(text), np.empty((0, 0)))
        if out is not None:
            r.save(out)
        return r
    d = lib.fit(rec(train), model, None if valid is None else rec(valid), split,
                valid_periodic, linear, None if linear_train is None else rec(linear_train),
                optimizer, generations, population, seed, lm_iterations, upsample, progress)
    r = FitResult(d["fit_json"], json.loads(d["fit_json"]), d["train_sim"], d["valid_sim"],
                  d["valid_rest_sim"])
    if out is not None:
        r.save(out)
    return r


@dataclasses.dataclass
class Prediction:
    """`predict`'s answer: the simulated outputs `y` (um, (outputs, n)) at the input
    record's times `t`; with measured outputs in the record, the RMSE over its last period
    per output and their mean (what `piezo predict` prints)."""

    t: np.ndarray
    y: np.ndarray
    rmse_last_period: Optional[list] = None
    rmse_mean: Optional[float] = None
    period_samples: Optional[int] = None


def predict(model, input: RecordLike, *, columns: Optional[dict] = None) -> Prediction:
    """`piezo predict --model MODEL --input INPUT`: simulates a saved model from rest on the
    inputs of a record. `model` is a `fit.json` path (or the folder holding it), a
    `FitResult`, or the text of a `fit.json`. The record's outputs are optional."""
    text, name = _model_text(model)
    rec = as_record(input, outputs_optional=True, columns=columns)
    d = _lib().predict(text, name, rec._native())
    return Prediction(rec.t, d["y"], d["rmse_last_period"], d["rmse_mean"],
                      d["period_samples"])


@dataclasses.dataclass
class Diagnosis:
    """`diagnose`'s answer. `report` is the JSON of `piezo diagnose --json` as a dict (the
    same for the same records); `cause` the first cause found (`none` if none), `causes` all
    of them, `gain` the relative RMSE gain of the extended model on the validation samples;
    `summary` the CLI's text report (also `str(diagnosis)`)."""

    report: dict
    summary: str

    @property
    def cause(self) -> str:
        return self.report["cause"]

    @property
    def causes(self) -> list:
        return self.report["causes"]

    @property
    def gain(self) -> float:
        return self.report["gain"]

    @property
    def base(self) -> dict:
        """The classical Bouc-Wen fit: model, RMSE on training and validation, parameters."""
        return self.report["base"]

    @property
    def extended(self) -> dict:
        """The base model extended by the causes found."""
        return self.report["extended"]

    @property
    def candidates(self) -> list:
        """Every extension tried: cause, round, RMSE, gain, evidence."""
        return self.report["candidates"]

    @property
    def findings(self) -> list:
        """The accepted causes with their evidence and confidence."""
        return self.report["findings"]

    def __str__(self) -> str:
        return self.summary


def _records(x) -> list:
    if x is None:
        return []
    if isinstance(x, list):
        return x
    return [x]


@dataclasses.dataclass
class BaseDiagnosis:
    """`diagnose(..., base=...)`'s answer. `report` is the JSON of `piezo diagnose --base
    --json` as a dict, `summary` its text report (also `str(...)`), `fit` the final model (the
    base with the causes named), whose `save` and `predict` work as for `fit`'s answer."""

    report: dict
    summary: str
    fit: FitResult

    @property
    def named(self) -> list:
        """Causes named (confirmed), in the order found."""
        return self.report["named"]

    @property
    def uncertain(self) -> list:
        """Causes that gained when fitted on all training records, not on half of them."""
        return self.report["uncertain"]

    @property
    def gain(self) -> float:
        """Relative gain of the final model over the base on the validation records
        (benchmark's official rule)."""
        return 1.0 - self.report["final_valid"] / self.report["base_valid"]

    def __str__(self) -> str:
        return self.summary


def _model_text(model) -> tuple:
    """`(text or None, name)` of a model given as a `FitResult`, the text of a `fit.json`,
    a `fit.json` path or the folder holding it."""
    if isinstance(model, FitResult):
        return model.fit_json, "<FitResult>"
    if isinstance(model, str) and model.lstrip().startswith("{"):
        return model, "<fit.json text>"
    p = pathlib.Path(model)
    return None, os.fspath(p / "fit.json" if p.is_dir() else p)


def diagnose(train, valid=None, *, split: Optional[float] = None,
             columns: Optional[dict] = None, consistency: bool = True, base=None):
    """`piezo diagnose --train TRAIN [--valid VALID | --split F]`: what the classical
    Bouc-Wen model misses on the stage, named as a cause, with its gain on the validation
    records. `train` and `valid` are a record or a list of records (one model fits all
    training records); without `valid` each training record is split at `split` (0.5).
    Like the CLI it checks itself on the other splits (or the swapped pair) and reports each
    cause as confident or uncertain (`report["consistency"]`); `consistency=False` skips that
    (`--no-consistency`).

    With `base` (a state-space `fit.json` of `piezo fit --model ss | hammerstein-ss |
    scheduled-ss | lfr`: path, folder, text or `FitResult`), `piezo diagnose --base`:
    discovery from that model on periodic records (`valid` required), returning a
    `BaseDiagnosis` with the extended model."""
    lib = _lib()
    rec = lambda r: as_record(r, columns=columns)._native()  # noqa: E731
    if base is not None:
        if valid is None or split is not None:
            raise InputError("base= needs valid records (periodic); split does not apply")
        text, name = _model_text(base)
        report, summary, fit_json = lib.diagnose_base(
            text, name, [rec(r) for r in _records(train)], [rec(r) for r in _records(valid)])
        ext = FitResult(fit_json, json.loads(fit_json), np.empty((0, 0)))
        return BaseDiagnosis(json.loads(report), summary, ext)
    text, summary = lib.diagnose([rec(r) for r in _records(train)],
                                 [rec(r) for r in _records(valid)], split, consistency)
    return Diagnosis(json.loads(text), summary)
