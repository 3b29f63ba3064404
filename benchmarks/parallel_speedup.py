"""Speed-up of running a matrix stage's seeds side by side (lfdt.parallel.run_jobs) against running them serially.

The jobs are what the translator stage runs: lfdt.translation.training.train_translator (G, D, frozen F and F^-1, the
kinematics of Y, held-out selection) on synthetic data of the real shapes, one job per seed. Both ways are timed
in one run, alternately, and the ratio of the medians reported: serial wall time / parallel wall time.
Writes benchmarks/results/parallel_speedup.json.
"""

from __future__ import annotations

import lfdt.numerics  # noqa: F401  (first: pins the numeric code paths before numpy, torch or mujoco load)

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np
import torch

from lfdt import layout, parallel
from lfdt.box_push_jobs.translator import box_push_kinematics
from lfdt.config import EnvConfig, TranslatorConfig
from lfdt.dynamics import DynamicsModels
from lfdt.tasks.box_push import columns as box_columns
from lfdt.translation.training import train_translator
from lfdt.translation.transitions import Transitions


def _transitions(n: int, rng: np.random.Generator) -> Transitions:
    x = rng.normal(size=(n, 21)).astype(np.float32)
    return Transitions(x=x, x2=x + 0.01, episode=np.arange(n) // 20, frame=np.arange(n) % 20, x_prev=x)


def translator_job(job: tuple[int, int], progress=None) -> float:
    """Train one translator for ``iterations`` on synthetic data (seed ``seed``); returns its wall time."""
    seed, iterations = job
    torch.set_num_threads(1)
    rng = np.random.default_rng(seed)
    demos = {p: _transitions(2_000, rng) for p in layout.PAIRINGS}
    held = {p: _transitions(200, rng) for p in layout.PAIRINGS}
    rand = {p: _transitions(20_000, rng) for p in layout.PAIRINGS}
    y = rng.normal(size=(20_000, 19)).astype(np.float32)
    dyn = DynamicsModels(19, 6, [256, 256, 256])
    cfg = TranslatorConfig(iterations=iterations, select_every=500, log_every=500)
    t0 = time.perf_counter()
    train_translator(demos, rand, y, dyn, cfg, seed=seed, progress=progress, held_out=held,
                     kinematics=box_push_kinematics(EnvConfig()), tl=box_columns.BOX_PUSH)
    return time.perf_counter() - t0


def timed(workers: int, seeds: int, iterations: int) -> float:
    t0 = time.perf_counter()
    parallel.run_jobs(translator_job, [(s, iterations) for s in range(seeds)], workers,
                      total=seeds * iterations, desc=f"{workers} worker(s)")
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seeds", type=int, default=3, help="jobs per stage instance (grid.seeds)")
    ap.add_argument("--iterations", type=int, default=3000)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--out", default="benchmarks/results/parallel_speedup.json")
    args = ap.parse_args()
    serial, par = [], []
    for _ in range(args.repeats):
        serial.append(timed(1, args.seeds, args.iterations))
        par.append(timed(2, args.seeds, args.iterations))
    res = {"benchmark": "matrix stage seeds: 2 worker processes vs serial, translator jobs",
           "seeds": args.seeds, "iterations": args.iterations, "repeats": args.repeats,
           "serial_s": serial, "parallel_s": par,
           "speedup": float(np.median(serial) / np.median(par)),
           "cpu_count": os.cpu_count(), "machine": platform.platform(), "torch": torch.__version__}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(res, indent=2) + "\n")
    print(json.dumps(res, indent=2))


if __name__ == "__main__":
    main()
