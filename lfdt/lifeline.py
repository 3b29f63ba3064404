"""A stage never outlives what started it, and two copies of one stage never run at once.

`dvc repro` runs a stage as a child process (through ``$SHELL -c``); a worker of a stage is a child of the stage.
Neither gets a signal when its launcher is killed (SIGKILL included): without a check they train on as orphans,
writing checkpoints and outputs under a rerun of the same stage. :func:`watch` ends this process within a second of
its launcher's death; :func:`stage_lock` makes a second copy of a stage wait for the first to go, then refuse.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import os
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path

from lfdt.errors import StageError

ORPHANED_EXIT = 3
"""The exit code of a process that ended because its launcher was gone."""
POLL_S = 0.5
LOCK_DIR = Path(tempfile.gettempdir()) / "lfdt-stage-locks"
"""Where stages hold their locks: this machine's (a lock is named after the stage's folder and command line, and
writes nothing into the workspace)."""
LOCK_WAIT_S = 30.0
"""How long a stage waits for another copy of itself to end (an orphan ends within a second of its launcher)."""


def _ancestors(pid: int) -> list[int]:
    out = []
    while pid > 1:
        try:
            with open(f"/proc/{pid}/stat") as fh:
                pid = int(fh.read().rsplit(")", 1)[1].split()[1])
        except (OSError, IndexError, ValueError):
            break
        out.append(pid)
    return out


def _cmdline(pid: int) -> list[str]:
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as fh:
            return [a.decode(errors="replace") for a in fh.read().split(b"\0") if a]
    except OSError:
        return []


def _start_time(pid: int) -> str | None:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[19]
    except (OSError, IndexError):
        return None


def launcher() -> int:
    """The process whose death should end this one: the nearest `dvc` above it (the shell DVC starts a stage through
    may stay alive without it), else the parent."""
    for pid in _ancestors(os.getpid()):
        args = _cmdline(pid)
        if any(Path(a).name == "dvc" for a in args[:3]) or args[1:3] == ["-m", "dvc"]:
            return pid
    return os.getppid()


_CLEANUPS: list = []


def on_orphaned(fn) -> None:
    """Call ``fn()`` (briefly: one second in all) before an orphaned process exits, e.g. to mark its runs KILLED."""
    _CLEANUPS.append(fn)


def watch(pid: int | None = None) -> int:
    """End this process (exit code :data:`ORPHANED_EXIT`) within a second of ``pid``'s death (default
    :func:`launcher`); returns the pid watched. A daemon thread: nothing to stop."""
    pid = pid or launcher()
    born = _start_time(pid)

    def alive() -> bool:
        return _start_time(pid) == born and born is not None  # a reused pid starts at another time

    def loop() -> None:
        while alive():
            time.sleep(POLL_S)
        done = threading.Thread(target=lambda: [fn() for fn in list(_CLEANUPS)], daemon=True)
        done.start()
        done.join(1.0)
        os._exit(ORPHANED_EXIT)

    if pid > 1 and born is not None:
        threading.Thread(target=loop, daemon=True, name="exit-with-launcher").start()
    return pid


@contextlib.contextmanager
def stage_lock(key: str, folder: Path, wait_s: float = LOCK_WAIT_S) -> Iterator[None]:
    """Hold an exclusive lock named after ``key`` (a stage's command line) in ``folder`` while the stage runs; a
    second holder waits up to ``wait_s`` seconds, then StageError names the process that has it."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / (hashlib.sha256(key.encode()).hexdigest()[:16] + ".lock")
    fh = open(path, "a+")  # noqa: SIM115 - held for the stage's life
    try:
        deadline = time.monotonic() + wait_s
        while True:
            try:
                fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if time.monotonic() > deadline:
                    fh.seek(0)
                    holder = fh.read().strip() or "another process"
                    raise StageError(f"this stage is already running ({holder}, lock {path}): `{key}`; wait for "
                                     "it to end, or stop it") from None
                time.sleep(POLL_S)
        fh.seek(0)
        fh.truncate()
        fh.write(f"pid {os.getpid()}")
        fh.flush()
        yield
    finally:
        fh.close()
