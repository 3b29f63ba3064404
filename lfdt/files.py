"""Atomic file writes: each writer writes ``.<name>.tmp-<pid>`` beside its target and renames it into place.

A process killed mid-write leaves its temporary file behind; the next write of the same target removes those of
processes that no longer run.
"""

from __future__ import annotations

import os
from pathlib import Path


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
