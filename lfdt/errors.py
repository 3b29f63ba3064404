"""Errors a stage reports as one line on stderr and exit code 2 (see :func:`lfdt.stage.main`), not as a traceback:
each names the file, key or argument at fault."""

INTERRUPTED = 130
"""Exit code of a command stopped by Ctrl-C (128 + SIGINT), as a shell reports it."""


def first_line(err: BaseException) -> str:
    """The first line of an exception's message (a library's may go on for lines), or its type's name when the
    message is empty: what a one-line error quotes of a cause."""
    text = str(err).strip()
    return text.splitlines()[0] if text else type(err).__name__


class StageError(Exception):
    """Base of the errors whose message says all a user needs."""


class DeviceError(StageError):
    """params.yaml names a torch device this machine does not have."""


class OutputError(StageError):
    """An output could not be written (a full disk, no permission, a read-only file system); names the file."""


class InputError(StageError):
    """A user-given file, folder or argument that cannot be used as it is (:mod:`lfdt.inputs`); names it and what
    was expected."""
