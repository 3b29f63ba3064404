"""Errors a stage reports as one line on stderr and exit code 2 (see :func:`lfdt.stage.main`), not as a traceback:
each names the file, key or argument at fault."""

import sys
from collections.abc import Callable

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


def one_line_errors(body: Callable[[], int], interrupted: str) -> int:
    """Run a command line's ``body`` (its exit code): a :class:`StageError` or an OSError (a full disk, no
    permission: :func:`lfdt.inputs.os_error_message`) is one line and exit 2, Ctrl-C one line saying ``interrupted``
    (what is left, how to go on) and :data:`INTERRUPTED`; anything else is a bug and raises."""
    try:
        return body()
    except StageError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"error: interrupted (Ctrl-C): {interrupted}", file=sys.stderr)
        return INTERRUPTED
    except OSError as err:
        from lfdt.inputs import os_error_message

        print(f"error: {os_error_message(err)}", file=sys.stderr)
        return 2
