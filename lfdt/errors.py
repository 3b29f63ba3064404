"""Errors a stage reports as one line on stderr and exit code 2 (see :func:`lfdt.stage.main`), not as a traceback:
each names the file, key or argument at fault."""

INTERRUPTED = 130
"""Exit code of a command stopped by Ctrl-C (128 + SIGINT), as a shell reports it."""


class StageError(Exception):
    """Base of the errors whose message says all a user needs."""


class DeviceError(StageError):
    """params.yaml names a torch device this machine does not have."""


class OutputError(StageError):
    """An output could not be written (a full disk, no permission, a read-only file system); names the file."""


class InputError(StageError):
    """A user-given file, folder or argument that cannot be used as it is (:mod:`lfdt.inputs`); names it and what
    was expected."""
