"""Atomic file writes: each writer writes ``.<name>.tmp-<pid>`` beside its target and renames it into place.

A process killed mid-write leaves its temporary file behind; the next write of the same target removes those of
processes that no longer run. A write that fails (a full disk, no permission) removes its temporary file and raises
:class:`~lfdt.errors.OutputError` naming the target (:func:`write_atomic`).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

from lfdt.errors import OutputError, StageError


def temp_path(path: str | Path) -> Path:
    """The temporary name this process writes ``path`` to, after removing leftovers of dead writers."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    for old in path.parent.glob(f".{path.name}.tmp-*"):
        pid = old.name.rsplit("-", 1)[1]
        if pid.isdigit() and int(pid) != os.getpid() and not process_alive(int(pid)):
            old.unlink(missing_ok=True)
    return path.with_name(f".{path.name}.tmp-{os.getpid()}")


def process_alive(pid: int) -> bool:
    """Whether a process with this id runs on this machine."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def write_atomic(path: str | Path, write: Callable[[Path], object]) -> Path:
    """``write(tmp)`` to this process's temporary name for ``path`` (:func:`temp_path`), then rename it into place.
    An OSError on the way (ENOSPC, EACCES, EROFS) removes the temporary file and becomes an OutputError that names
    ``path``: the OS's own error names no file when a write, rather than an open, fails."""
    path = Path(path)
    tmp = None
    try:
        tmp = temp_path(path)
        write(tmp)
        os.replace(tmp, path)
    except OSError as err:
        if tmp is not None:
            tmp.unlink(missing_ok=True)
        if isinstance(err, StageError):  # already names its file
            raise
        raise OutputError(f"{path}: cannot write it: {err.strerror or err}") from None
    return path
