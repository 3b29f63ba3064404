"""Independent jobs of one stage side by side in worker processes, with one progress bar.

DVC runs one stage at a time, so a matrix stage that trains several seeds is where the second core of a
laptop-class CPU earns its keep: :func:`run_jobs` runs the seeds ``workers`` at a time, each in its own
process (``spawn``: no state shared with the parent), and gathers their results in job order. A job that
fails stops the stage with the job named; with ``workers=1`` the jobs run one after the other in this process
(the serial baseline of ``benchmarks/parallel_speedup.py``).
"""

from __future__ import annotations

import multiprocessing as mp
import queue
import sys
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_EXCEPTION, ProcessPoolExecutor, wait
from typing import Any, Protocol

from tqdm import tqdm


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


def _call(fn: Callable[[Any, Progress], Any], job: Any, progress: _QueueProgress) -> Any:
    try:
        return fn(job, progress)
    finally:
        progress.flush()


def run_jobs(fn: Callable[[Any, Progress], Any], jobs: Sequence[Any], workers: int, total: int | None = None,
             desc: str = "jobs", unit: str = "it") -> list[Any]:
    """``fn(job, progress)`` for every job, ``workers`` processes at a time; results in job order.

    ``fn`` must be importable by name (a module-level function) and ``job`` picklable. ``total`` is the
    progress bar's length (the sum of what the jobs report).
    """
    bar = tqdm(total=total, desc=desc, unit=unit, unit_scale=True, mininterval=1.0, dynamic_ncols=True,
               file=sys.stderr)
    try:
        if workers <= 1 or len(jobs) <= 1:
            return [fn(job, bar) for job in jobs]
        ctx = mp.get_context("spawn")
        with ctx.Manager() as manager:
            q = manager.Queue()
            done = threading.Event()

            def pump() -> None:
                while not done.is_set():
                    try:
                        bar.update(q.get(timeout=0.2))
                    except queue.Empty:
                        continue

            reader = threading.Thread(target=pump, daemon=True)
            reader.start()
            try:
                with ProcessPoolExecutor(max_workers=min(workers, len(jobs)), mp_context=ctx) as pool:
                    futures = [pool.submit(_call, fn, job, _QueueProgress(q)) for job in jobs]
                    finished, _ = wait(futures, return_when=FIRST_EXCEPTION)
                    for i, f in enumerate(futures):
                        if f.done() and f.exception() is not None:
                            for other in futures:
                                other.cancel()
                            raise RuntimeError(f"job {jobs[i]!r} failed: {f.exception()}") from f.exception()
                    return [f.result() for f in futures]
            finally:
                done.set()
                reader.join()
                while True:  # what the workers reported after the reader stopped
                    try:
                        bar.update(q.get_nowait())
                    except queue.Empty:
                        break
    finally:
        bar.close()
