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
LOCK_DIR = Path(tempfile.gettempdir()) / f"lfdt-stage-locks-{os.getuid()}"
"""Where stages hold their locks: this machine's, this user's (a lock is named after the stage's folder and command
line, and writes nothing into the workspace)."""
DVC_STAGE_ENV = "DVC_STAGE"
"""Set by DVC for every stage command it runs: a stage without it was started by hand and lives as its user says."""
SHELLS = frozenset({"sh", "bash", "dash", "zsh", "ksh", "fish"})
"""Programs DVC may run a stage's command through (``$SHELL -c``)."""
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
    """When ``pid`` started (clock ticks after boot), or None when it is gone or has died and waits to be reaped (a
    zombie: a launcher killed while its stage still holds its output pipe stays one until the stage ends)."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            fields = fh.read().rsplit(")", 1)[1].split()
    except OSError:
        return None
    if len(fields) < 20 or fields[0] in ("Z", "X"):
        return None
    return fields[19]


def _is_dvc(args: list[str]) -> bool:
    return any(Path(a).name == "dvc" for a in args[:3]) or args[1:3] == ["-m", "dvc"]


ORPHANED = 0
"""What :func:`launcher_in` says when the `dvc` that started this process is already gone."""


def launcher_in(chain: list[tuple[int, list[str]]], parent: int) -> int:
    """The launcher to watch among the ``(pid, command line)`` of this process's ancestors, nearest first, for a
    process DVC started: the nearest `dvc`; else :data:`ORPHANED` when only shells (and init) lie between this process
    and init, as when the `dvc` that started it died while it was starting; else ``parent`` (another program ran DVC
    through its Python API)."""
    for pid, args in chain:
        if _is_dvc(args):
            return pid
    if all(Path((args or ["?"])[0]).name.lstrip("-") in SHELLS for pid, args in chain if pid > 1):
        return ORPHANED
    return parent


def launcher() -> int | None:
    """The process whose death should end this one (:func:`launcher_in`; an orphan exits at once), or None when none
    should: a process DVC did not start (``DVC_STAGE`` unset: by hand, or a test calling a stage in-process) lives as
    its user says."""
    if DVC_STAGE_ENV not in os.environ:
        return None
    pid = launcher_in([(p, _cmdline(p)) for p in _ancestors(os.getpid())], os.getppid())
    if pid == ORPHANED:
        _orphaned()
    return pid


_CLEANUPS: list = []


def on_orphaned(fn) -> None:
    """Call ``fn()`` (briefly: one second in all) before an orphaned process exits, e.g. to mark its runs KILLED."""
    _CLEANUPS.append(fn)


def _orphaned() -> None:
    """Run the clean-ups (one second in all), then end this process with :data:`ORPHANED_EXIT`."""
    done = threading.Thread(target=lambda: [fn() for fn in list(_CLEANUPS)], daemon=True)
    done.start()
    done.join(1.0)
    os._exit(ORPHANED_EXIT)


_WATCHED: set[int] = set()


def watch(pid: int | None = None) -> int | None:
    """End this process (exit code :data:`ORPHANED_EXIT`) within a second of ``pid``'s death; returns the pid
    watched. Without ``pid``, :func:`launcher` says which (None: nothing is watched). A given ``pid`` that is already
    gone ends this process at once (a worker whose stage ended while it started). A daemon thread: nothing to stop;
    a second call for the same pid adds none."""
    pid = pid if pid is not None else launcher()
    if pid is None or pid <= 1:
        return None
    born = _start_time(pid)
    if born is None:
        _orphaned()
    if pid in _WATCHED:
        return pid
    _WATCHED.add(pid)

    def loop() -> None:
        while _start_time(pid) == born:  # a reused pid starts at another time
            time.sleep(POLL_S)
        _orphaned()

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
