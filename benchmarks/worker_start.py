"""What starting a matrix stage's workers costs: ``forkserver`` (lfdt.parallel's default) against ``spawn``, and
against a forkserver that preloads nothing (``forkserver_bare``: what Python 3.11 gave before run_jobs named the
modules to preload).

Each measurement is a fresh process, as a stage is: it imports what the translator stage imports (torch, MLflow,
MuJoCo, the job's code), then runs two tiny jobs in two workers through lfdt.parallel.run_jobs; each job imports
MLflow, as a job that opens its run does. With ``spawn`` each worker imports all of that again; with ``forkserver``
one server process does, and the workers are its forks; with ``forkserver_bare`` each fork imports it again. The
ways are timed in one run, alternately; reported: the medians of each and the ratios (spawn / forkserver,
forkserver_bare / forkserver), with the CPU time of the whole process tree. The whole smoke DAG
(tests/smoke_params.yaml) is where it adds up: ``--smoke N``
also times N `dvc repro` of it each way, alternately, each in a fresh copy of the project (about 4 minutes each on a
2-core CPU). Writes benchmarks/results/worker_start.json.
"""

from __future__ import annotations

import lfdt.numerics  # noqa: F401  (first: pins the numeric code paths before numpy, torch or mujoco load)

import argparse
import datetime
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import lfdt.box_push_jobs.translator  # noqa: F401  (what a translator stage's process has loaded)
from lfdt import numerics, parallel

ROOT = Path(__file__).resolve().parents[1]
METHODS = ("spawn", "forkserver", "forkserver_bare")
SMOKE_METHODS = ("spawn", "forkserver")
PRELOAD = ("lfdt.box_push_jobs.translator",)
"""What a translator stage's server imports for its job (the benchmark's job lives in this script, which Python 3.11's
server cannot preload)."""


def tiny_job(job: int, progress=None) -> int:
    """A job that does next to nothing but import what a job opening its MLflow run imports: what is timed is the
    workers' start."""
    import mlflow  # noqa: F401
    import torch

    return int(torch.arange(job + 3).sum())


def _child(method: str) -> None:
    from lfdt.mlflow_runs import worker_modules

    preload = () if method == "forkserver_bare" else (*PRELOAD, *worker_modules())
    out = parallel.run_jobs(tiny_job, [0, 1], workers=2, method=method.removesuffix("_bare"), desc=method,
                            preload=preload)
    assert out == [3, 6], out


def _timed(cmd: list[str], cwd: Path, env: dict) -> tuple[float, float]:
    """Wall and CPU seconds of one command: CPU summed over its whole process tree, sampled every 50 ms (a forkserver
    and its workers are no children this process could wait for; a process's last < 50 ms may go uncounted)."""
    import psutil

    cpu: dict[tuple[int, float], float] = {}
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=cwd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    root = psutil.Process(proc.pid)
    while proc.poll() is None:
        try:
            tree = [root, *root.children(recursive=True)]
        except psutil.NoSuchProcess:
            tree = []
        for p in tree:
            try:
                with p.oneshot():
                    c = p.cpu_times()
                    cpu[(p.pid, p.create_time())] = c.user + c.system
            except psutil.Error:
                continue
        time.sleep(0.05)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise subprocess.CalledProcessError(proc.returncode, cmd)
    return wall, sum(cpu.values())


def _smoke(method: str, tmp: Path) -> tuple[float, float]:
    """One `dvc repro` of the smoke params in a fresh copy of the project, workers started by ``method``."""
    sys.path.insert(0, str(ROOT / "tests"))
    import shutil

    import smoke

    shutil.rmtree(tmp / method, ignore_errors=True)
    root = smoke.make_project(tmp / method)
    env = {**os.environ, parallel.START_METHOD_VAR: method, "DVC_NO_ANALYTICS": "1", "MUJOCO_GL": "egl",
           "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}"}
    return _timed([sys.executable, "-m", "dvc", "repro"], root, env)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--child", choices=METHODS, help=argparse.SUPPRESS)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--smoke", type=int, default=0, help="also time this many smoke DAG runs each way")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "worker_start.json")
    args = ap.parse_args()
    if args.child:
        _child(args.child)
        return
    times: dict[str, dict[str, list[float]]] = {m: {"wall_s": [], "cpu_s": []} for m in METHODS}
    for _ in range(args.repeats):
        for m in METHODS:
            wall, cpu = _timed([sys.executable, __file__, "--child", m], ROOT, dict(os.environ))
            times[m]["wall_s"].append(wall)
            times[m]["cpu_s"].append(cpu)
            print(f"{m}: {wall:.2f} s wall, {cpu:.2f} s CPU", file=sys.stderr)
    smoke: dict[str, dict[str, list[float]]] = {m: {"wall_s": [], "cpu_s": []} for m in SMOKE_METHODS}
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(args.smoke):
            for m in SMOKE_METHODS:
                wall, cpu = _smoke(m, Path(tmp))
                smoke[m]["wall_s"].append(wall)
                smoke[m]["cpu_s"].append(cpu)
                print(f"smoke DAG, {m}: {wall:.1f} s wall, {cpu:.1f} s CPU", file=sys.stderr)
    med = {m: {k: float(np.median(v)) for k, v in times[m].items()} for m in METHODS}
    info = numerics.describe()
    res = {"benchmark": "a stage process that runs two tiny jobs in two workers: spawn, forkserver, forkserver with "
                        "nothing preloaded",
           "repeats": args.repeats, "times": times, "median": med,
           "ratio_wall_spawn_over_forkserver": med["spawn"]["wall_s"] / med["forkserver"]["wall_s"],
           "ratio_cpu_spawn_over_forkserver": med["spawn"]["cpu_s"] / med["forkserver"]["cpu_s"],
           "ratio_wall_bare_over_forkserver": med["forkserver_bare"]["wall_s"] / med["forkserver"]["wall_s"],
           "ratio_cpu_bare_over_forkserver": med["forkserver_bare"]["cpu_s"] / med["forkserver"]["cpu_s"],
           "smoke_runs": args.smoke, "smoke": smoke,
           "smoke_ratio_wall_spawn_over_forkserver": (float(np.median(smoke["spawn"]["wall_s"])
                                                       / np.median(smoke["forkserver"]["wall_s"]))
                                                      if args.smoke else None),
           "cpu_model": info["cpu_model"], "cpu_isa": info["cpu_isa"], "cores": os.cpu_count(),
           "date": datetime.date.today().isoformat()}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(res, indent=2) + "\n")
    print(json.dumps({k: v for k, v in res.items() if k != "times"}, indent=2))


if __name__ == "__main__":
    main()
