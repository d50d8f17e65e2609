"""The exceptions of the identification functions (`piezo.fit`, `predict`, `diagnose`,
`read_record`). Their message is the one the `piezo` CLI prints after `error: `."""


class PiezoIdentError(Exception):
    """Base of the identification errors."""


class InputError(PiezoIdentError, ValueError):
    """A record, model or option the library refuses: a missing column, a unit of the wrong
    quantity, too few samples, a `fit.json` of another kind, an unknown model name, ..."""


class FileError(PiezoIdentError, OSError):
    """A file that could not be read or written."""
