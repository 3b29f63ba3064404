"""The smoke DAG's whole `dvc repro` (most of `make test`'s time) with this working tree's code against another
commit's, in one run.

Each version is copied into a temporary folder with the smoke params (tests/smoke_params.yaml laid over its
params.yaml, as tests/smoke.py does), then `dvc repro --force` of each is timed alternately, ``--repeats`` times (the
first is a fresh project's build, as `make test`'s): wall time, and the CPU time of the whole process tree (DVC, every
stage, their forkservers and workers; lfdt.parallel's workers are no children a process could wait for, so the tree
is sampled, as benchmarks/worker_start.py does). Each version's stages import its own lfdt (PYTHONPATH). The tiny
Table I, the twin's table and the fingerprint must come out byte for byte the same from both. Writes
benchmarks/results/smoke_against.json.

    python benchmarks/smoke_against.py --against 097b729     # before the workers' forkserver preloaded anything
"""

from __future__ import annotations

import lfdt.numerics  # noqa: F401  (first: pins the numeric code paths before numpy, torch or mujoco load)

import argparse
import datetime
import json
import os
import statistics
import sys
import tempfile
from pathlib import Path

from noop_shapes import ROOT, _run, checkout
from worker_start import _timed

from lfdt import numerics

COMPARED = ("reports/table1.csv", "reports/table1_runs.csv", "reports/twin_runs.csv", "reports/fingerprint.json")
"""Outputs both versions must write byte for byte alike."""


def timed_repro(cwd: Path) -> tuple[float, float]:
    """Wall and CPU seconds of `dvc repro --force` in ``cwd``, with that version's lfdt first on the path."""
    env = {**os.environ, "PYTHONPATH": str(cwd), "MLFLOW_TRACKING_URI": f"sqlite:///{cwd / 'mlflow.db'}",
           "DVC_NO_ANALYTICS": "1", "MUJOCO_GL": "egl", "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}"}
    return _timed([sys.executable, "-m", "dvc", "repro", "--force"], cwd, env)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--against", required=True, help="the commit to compare with (e.g. the one before a change)")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks/results/smoke_against.json")
    args = ap.parse_args()
    rev = _run(["git", "rev-parse", "--short", args.against], ROOT).strip()
    with tempfile.TemporaryDirectory() as tmp:
        # the smoke params as they are (their own demo counts), built by the timed runs
        versions = {name: checkout(r, Path(tmp) / d, demos=None, repro=False)
                    for name, r, d in (("working tree", None, "new"), (rev, rev, "old"))}
        times: dict[str, dict[str, list[float]]] = {k: {"wall_s": [], "cpu_s": []} for k in versions}
        for _ in range(args.repeats):
            for name, cwd in versions.items():
                wall, cpu = timed_repro(cwd)
                times[name]["wall_s"].append(wall)
                times[name]["cpu_s"].append(cpu)
                print(f"{name}: {wall:.1f} s wall, {cpu:.1f} s CPU", file=sys.stderr)
        same = {f: len({(cwd / f).read_bytes() for cwd in versions.values()}) == 1 for f in COMPARED}
    med = {k: {m: statistics.median(v) for m, v in t.items()} for k, t in times.items()}
    info = numerics.describe()
    result = {"benchmark": "the smoke DAG's dvc repro --force: this working tree against another commit",
              "against": rev, "repeats": args.repeats, "times": times, "median": med,
              "ratio_wall_against_over_working_tree": med[rev]["wall_s"] / med["working tree"]["wall_s"],
              "ratio_cpu_against_over_working_tree": med[rev]["cpu_s"] / med["working tree"]["cpu_s"],
              "identical_outputs": same, "cpu_model": info["cpu_model"], "cpu_isa": info["cpu_isa"],
              "cores": os.cpu_count(), "date": datetime.date.today().isoformat()}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps({k: v for k, v in result.items() if k != "times"}, indent=2))
    if not all(same.values()):
        raise SystemExit(f"the two versions' outputs differ: {[f for f, ok in same.items() if not ok]}")


if __name__ == "__main__":
    main()
