"""A no-op `dvc repro` of this working tree's DAG against another commit's, both built on tiny params, in one run.

The time of a no-op repro depends on the shape of the DAG (stages, deps, outputs, params per stage), not on what
the stages compute. So each of the two versions is copied into a temporary folder with the smoke params
(tests/smoke_params.yaml laid over its params.yaml) but the default grid's demo counts, i.e. the default DAG's
stages on a few minutes of compute; each is reproduced once, then their no-op repros are timed alternately, with
nothing else changed between them. Writes benchmarks/results/noop_shapes.json.

    python benchmarks/noop_shapes.py --against e9f4cb0     # the last commit before the stages were merged
"""

from __future__ import annotations

import lfdt.numerics  # noqa: F401  (first: pins the numeric code paths before numpy, torch or mujoco load)

import argparse
import io
import json
import os
import platform
import shutil
import statistics
import subprocess
import tarfile
import tempfile
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
FILES = ("dvc.yaml", "params.yaml", "lfdt", "stages", "data/real", "tests/smoke_params.yaml")
"""What a version's DAG needs to run (the smoke params file only to build its params)."""
COMPARED = ("reports/table1.csv", "reports/table1_runs.csv", "reports/translator_diagnostics.csv")
"""Outputs both versions must write byte for byte alike (the twin's are left out: its settings may differ)."""
DEMOS = [2, 3, 4]
"""Three demo counts, as the default grid has, within the smoke params' 4 demonstrations per pairing."""


def _run(args: list[str], cwd: Path) -> str:
    # each version's stages import its own lfdt, not the editable install's
    env = {**os.environ, "PYTHONPATH": str(cwd), "MLFLOW_TRACKING_URI": f"sqlite:///{cwd / 'mlflow.db'}"}
    out = subprocess.run(args, cwd=cwd, capture_output=True, text=True, env=env)
    if out.returncode:
        raise SystemExit(f"`{' '.join(args)}` failed in {cwd}:\n{out.stdout[-2000:]}\n{out.stderr[-2000:]}")
    return out.stdout


def _merge(base: dict, over: dict) -> dict:
    out = dict(base)
    for k, v in over.items():
        out[k] = _merge(base[k], v) if isinstance(v, dict) and isinstance(base.get(k), dict) else v
    return out


def checkout(rev: str | None, dst: Path, demos: list[int] | None = DEMOS, repro: bool = True) -> Path:
    """The files of ``rev`` (None: this working tree) in ``dst``, with the tiny params, as a git + DVC project:
    ``demos`` the grid's demo counts (None: the smoke params' own), reproduced once when ``repro``."""
    dst.mkdir(parents=True)
    if rev is None:
        for name in FILES:
            src = ROOT / name
            if src.is_dir():
                shutil.copytree(src, dst / name, ignore=shutil.ignore_patterns("__pycache__"))
            else:
                (dst / name).parent.mkdir(parents=True, exist_ok=True)
                shutil.copy(src, dst / name)
    else:
        archive = subprocess.run(["git", "archive", rev, *FILES], cwd=ROOT, capture_output=True, check=True).stdout
        tarfile.open(fileobj=io.BytesIO(archive)).extractall(dst, filter="data")
    params = _merge(yaml.safe_load((dst / "params.yaml").read_text()),
                    yaml.safe_load((dst / "tests/smoke_params.yaml").read_text()))
    if demos is not None:
        params["grid"]["demos"] = demos
    (dst / "params.yaml").write_text(yaml.safe_dump(params, sort_keys=False))
    _run(["git", "init", "-q"], dst)
    _run(["dvc", "init", "-q"], dst)
    _run(["dvc", "config", "core.analytics", "false"], dst)
    if repro:
        _run(["dvc", "repro", "-q"], dst)
    return dst


def timed_noop(cwd: Path) -> float:
    import time

    t0 = time.perf_counter()
    out = _run(["dvc", "repro"], cwd)
    wall = time.perf_counter() - t0
    if "Running stage" in out:
        raise SystemExit(f"`dvc repro` in {cwd} had something to do:\n{out[-1000:]}")
    return wall


def shape(cwd: Path) -> dict:
    lock = yaml.safe_load((cwd / "dvc.lock").read_text())["stages"]
    n = len(lock)
    return {"stages": n, "deps": sum(len(s.get("deps", [])) for s in lock.values()),
            "outs": sum(len(s.get("outs", [])) for s in lock.values()),
            "lock_bytes": (cwd / "dvc.lock").stat().st_size}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--against", required=True, help="the commit to compare with (e.g. the one before a change)")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--out", default=str(ROOT / "benchmarks/results/noop_shapes.json"))
    args = ap.parse_args()
    rev = _run(["git", "rev-parse", "--short", args.against], ROOT).strip()
    with tempfile.TemporaryDirectory() as tmp:
        versions = {"working tree": checkout(None, Path(tmp) / "new"), rev: checkout(rev, Path(tmp) / "old")}
        times: dict[str, list[float]] = {k: [] for k in versions}
        for _ in range(args.repeats):
            for name, cwd in versions.items():
                times[name].append(timed_noop(cwd))
        shapes = {k: shape(v) for k, v in versions.items()}
        # the DAG's shape must not change what it computes: Table I of the tiny params, byte for byte
        same = {f: len({(cwd / f).read_bytes() for cwd in versions.values()}) == 1 for f in COMPARED}
    med = {k: statistics.median(v) for k, v in times.items()}
    result = {"benchmark": "no-op dvc repro of two versions of the DAG, both on tiny params with the default grid's "
                           "demo counts (the default DAG's stages)",
              "against": rev, "repeats": args.repeats, "shapes": shapes, "times_s": times, "median_s": med,
              "ratio_working_tree_over_against": med["working tree"] / med[rev], "identical_outputs": same,
              "machine": platform.platform(), "dvc": _run(["dvc", "--version"], ROOT).strip()}
    Path(args.out).write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps({k: result[k] for k in ("shapes", "median_s", "ratio_working_tree_over_against",
                                              "identical_outputs")}, indent=2))


if __name__ == "__main__":
    main()
