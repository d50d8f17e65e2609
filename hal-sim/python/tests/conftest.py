"""Where the tests find the measured records and the `piezo` CLI they compare against.

`PIEZO_DATA`: the records (default `<repository>/../shared/data`); `PIEZO_BIN`: the CLI
(default `<repository>/target/release/piezo`). Missing, the tests that need them skip,
unless `PIEZO_REQUIRE=1` (the CI step sets it): then they fail.
"""
import os
import pathlib
import subprocess

import pytest

REPO = pathlib.Path(__file__).resolve().parents[3]


def _need(path: pathlib.Path, what: str) -> pathlib.Path:
    if not path.exists():
        msg = f"{what} not found at {path}"
        if os.environ.get("PIEZO_REQUIRE") == "1":
            pytest.fail(msg)
        pytest.skip(msg)
    return path


@pytest.fixture(scope="session")
def data_dir() -> pathlib.Path:
    return _need(pathlib.Path(os.environ.get("PIEZO_DATA", REPO.parent / "shared" / "data")),
                 "the measured records (PIEZO_DATA)")


@pytest.fixture(scope="session")
def piezo_cli():
    """Runs the `piezo` CLI: `piezo_cli("diagnose", "--train", p)` returns the completed
    process (stdout, stderr and the exit code, not checked)."""
    exe = _need(pathlib.Path(os.environ.get("PIEZO_BIN", REPO / "target" / "release" / "piezo")),
                "the piezo CLI (PIEZO_BIN)")

    def run(*args):
        return subprocess.run([str(exe), *map(str, args)], capture_output=True, text=True,
                              timeout=900)

    return run


@pytest.fixture(scope="session")
def backlash(data_dir) -> pathlib.Path:
    """Measured flexure micromanipulator, 1 Hz sine at 200 Hz (8 027 samples)."""
    return data_dir / "backlash-micromanipulator" / "model_1Hz.csv"
