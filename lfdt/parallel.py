"""Independent jobs of one stage side by side in worker processes, with one progress bar.

DVC runs one stage at a time, so a matrix stage that trains several seeds is where the second core of a
laptop-class CPU earns its keep: :func:`run_jobs` runs the seeds ``workers`` at a time, each in its own
process, and gathers their results in job order. A job that fails stops the stage with the job named; with
``workers=1`` the jobs run one after the other in this process (the serial baseline of
``benchmarks/parallel_speedup.py``).

The workers start by ``forkserver`` (:func:`start_method`): a fresh server process imports the job's module and
what the workers import beyond it (``preload``: MLflow and its store) once, then each worker is a fork of it. Nothing
is shared with the stage process, as with ``spawn``, but the workers do not each import torch and MLflow again: a
small stage's start is where that shows (``benchmarks/worker_start.py``), and every result is the same bits either
way. The modules are named to the server explicitly: Python 3.11's server never imports the stage's script itself
(CPython gh-126631: it looks for a ``main_path`` key the preparation data does not have), so each worker used to
import everything on its own.
"""

from __future__ import annotations

import importlib
import multiprocessing as mp
import os
import queue
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_EXCEPTION, ProcessPoolExecutor, wait
from dataclasses import dataclass
from typing import Any, Protocol

from tqdm import tqdm

from lfdt import lifeline
from lfdt.errors import StageError
from lfdt.inputs import env_choice


class Progress(Protocol):
    """What a job reports its work through (a tqdm bar has this method)."""

    def update(self, n: int = 1) -> object: ...


class _QueueProgress:
    """Picklable progress of a worker: sends its increments to the parent's bar about twice a second."""

    def __init__(self, q):
        self.q = q
        self.pending = 0
        self.last = 0.0

    def update(self, n: int = 1) -> None:
        self.pending += n
        now = time.monotonic()
        if now - self.last > 0.5:
            self.flush()
            self.last = now

    def flush(self) -> None:
        if self.pending:
            self.q.put(self.pending)
            self.pending = 0


START_METHOD_VAR = "LFDT_WORKER_START"
"""Environment variable: how a matrix stage starts its workers, ``forkserver`` (default) or ``spawn`` (the
benchmark's baseline); another value is a one-line error naming it."""


def start_method() -> str:
    """How :func:`run_jobs` starts its workers: :data:`START_METHOD_VAR`, else ``forkserver`` (``spawn`` where the
    platform has no forkserver)."""
    default = "forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn"
    return env_choice(START_METHOD_VAR, ("forkserver", "spawn"), default)

_PROGRESS_QUEUE = None
"""In a worker: the queue its jobs' progress goes to (set by :func:`_init_worker`)."""


def _init_worker(parent: int, q) -> None:
    """Worker initializer: keep the progress queue (a pool's workers can get a queue only by inheritance), and end
    this worker as soon as the stage process that started it is gone. A pool's workers get no signal when their
    parent is killed, and would otherwise train on as orphans, writing the stage's checkpoints and outputs under a
    rerun of the same stage."""
    global _PROGRESS_QUEUE
    _PROGRESS_QUEUE = q
    # Ctrl-C raises KeyboardInterrupt in the job again: the server handed on its quiet exit (lfdt.forkserver_signals)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    lifeline.watch(parent)


def _describe(job: Any) -> str:
    """A job in an error message: its ``name`` (or each of a group's names) where it has one, else its repr, short."""
    names = [getattr(j, "name", None) for j in (job if isinstance(job, list | tuple) else [job])]
    text = ", ".join(n for n in names if isinstance(n, str)) or repr(job)
    return text if len(text) <= 200 else text[:197] + "..."


@dataclass(frozen=True)
class Job:
    """A job function named by its module and name: the stage process that runs it need not import that module
    (torch, MuJoCo and the job's code take seconds to import; a worker's forkserver imports them once). A stage names
    its job this way where it needs nothing else from the module; tests/test_dvc_deps.py counts the named module as
    one the stage imports."""

    module: str
    """The job's module, ``lfdt.box_push_jobs.bc``."""
    name: str
    """The function in it, called as ``fn(job, progress)``."""

    def __call__(self, job: Any, progress: Progress) -> Any:
        return getattr(importlib.import_module(self.module), self.name)(job, progress)


def _call(fn: Callable[[Any, Progress], Any], job: Any) -> Any:
    progress = _QueueProgress(_PROGRESS_QUEUE)
    try:
        return fn(job, progress)
    finally:
        progress.flush()


STOP_WAIT_S = 10.0
"""How long a worker stopped after another job failed may take to end before it is killed."""


def _stop(pool: ProcessPoolExecutor, futures: list) -> None:
    """Cancel the jobs not started and end the workers still running theirs: a stage whose job failed reports it now,
    not after its other jobs have trained for minutes in vain. ProcessPoolExecutor has no public way to stop a running
    job (its shutdown waits for them), hence its ``_processes``; SIGTERM ends a worker at once (a killed job's MLflow
    run is marked KILLED when the rerun opens its run of the same name: :func:`lfdt.mlflow_runs.mark_killed_runs`)."""
    for f in futures:
        f.cancel()
    procs = list((getattr(pool, "_processes", None) or {}).values())
    for p in procs:
        p.terminate()
    deadline = time.monotonic() + STOP_WAIT_S
    for p in procs:
        p.join(max(0.0, deadline - time.monotonic()))
        if p.is_alive():
            p.kill()


def run_jobs(fn: Callable[[Any, Progress], Any], jobs: Sequence[Any], workers: int, total: int | None = None,
             desc: str = "jobs", unit: str = "it", method: str | None = None,
             preload: Sequence[str] | None = None) -> list[Any]:
    """``fn(job, progress)`` for every job, ``workers`` processes at a time; results in job order.

    ``fn`` must be importable by name (a module-level function, or a :class:`Job`) and ``job`` picklable. ``total``
    is the progress bar's length (the sum of what the jobs report); ``method`` how the workers start (``forkserver`` or
    ``spawn``; None: :func:`start_method`); ``preload`` the modules, beyond ``fn``'s, that a forkserver imports once
    for all its workers (None: what a job's MLflow run imports, :func:`lfdt.mlflow_runs.worker_modules`; the first
    call of a process decides: its server serves the later ones).
    """
    bar = tqdm(total=total, desc=desc, unit=unit, unit_scale=True, mininterval=1.0, dynamic_ncols=True,
               file=sys.stderr)
    try:
        if workers <= 1 or len(jobs) <= 1:
            return [fn(job, bar) for job in jobs]
        ctx = mp.get_context(method or start_method())
        if ctx.get_start_method() == "forkserver":
            if preload is None:
                from lfdt.mlflow_runs import worker_modules

                preload = worker_modules()
            # lfdt.forkserver_signals first (a Ctrl-C while the server imports is silent), then lfdt.numerics: its pins
            # must precede numpy's and torch's import in the server as everywhere
            module = fn.module if isinstance(fn, Job) else fn.__module__
            ctx.set_forkserver_preload(["lfdt.forkserver_signals", "lfdt.numerics", module, *preload])
        q = ctx.Queue()
        done = threading.Event()

        def pump() -> None:
            while not done.is_set():
                try:
                    bar.update(q.get(timeout=0.2))
                except queue.Empty:
                    continue

        reader = threading.Thread(target=pump, daemon=True)
        reader.start()
        pool = ProcessPoolExecutor(max_workers=min(workers, len(jobs)), mp_context=ctx, initializer=_init_worker,
                                   initargs=(os.getpid(), q))
        try:
            futures = [pool.submit(_call, fn, job) for job in jobs]
            wait(futures, return_when=FIRST_EXCEPTION)
            for i, f in enumerate(futures):
                if f.done() and f.exception() is not None:
                    _stop(pool, futures)
                    err = f.exception()
                    if isinstance(err, StageError):  # its message names the file or key: the stage's one line
                        raise err
                    raise RuntimeError(f"job {i + 1} of {len(jobs)} ({_describe(jobs[i])}) failed: "
                                       f"{type(err).__name__}: {err}") from err
            return [f.result() for f in futures]
        finally:
            pool.shutdown(wait=True, cancel_futures=True)  # after _stop: at once
            done.set()
            reader.join()
            while True:  # what the workers reported after the reader stopped
                try:
                    bar.update(q.get(timeout=0.05))
                except queue.Empty:
                    break
    finally:
        bar.close()
