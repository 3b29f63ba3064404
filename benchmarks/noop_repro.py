"""Where a `dvc repro` with nothing to do spends its time: this pipeline against DVC's own floor, in one run.

The pipeline's no-op repro is timed in the repository, or in the project ``--project`` names (it must be up to
date: `dvc status` clean). The floor is a throwaway DVC project in a temporary folder with the same number of
stages, each with the same number of code dependencies, params and outputs as the pipeline's average stage, but
trivial files: what DVC costs per stage no matter what a stage does. A second floor with half the dependencies
per stage and one with half the stages tell what each costs. Both ways are timed alternately; medians are
reported, and the ratio pipeline / floor.
Writes benchmarks/results/noop_repro.json.
"""

from __future__ import annotations

import lfdt.numerics  # noqa: F401  (first: pins the numeric code paths before numpy, torch or mujoco load)

import argparse
import json
import platform
import shutil
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]


def _dvc(args: list[str], cwd: Path) -> str:
    out = subprocess.run(["dvc", *args], cwd=cwd, capture_output=True, text=True)
    if out.returncode:
        raise SystemExit(f"`dvc {' '.join(args)}` failed in {cwd}:\n{out.stderr}")
    return out.stdout


def _timed_noop(cwd: Path) -> float:
    t0 = time.perf_counter()
    out = _dvc(["repro"], cwd)
    wall = time.perf_counter() - t0
    if "up to date" not in out:
        raise SystemExit(f"`dvc repro` in {cwd} had something to do; run it once first:\n{out[-500:]}")
    return wall


def pipeline_shape(root: Path) -> dict:
    """Stages, and per stage the mean number of deps, outputs (outs, metrics, plots) and params keys, from dvc.lock."""
    lock = yaml.safe_load((root / "dvc.lock").read_text())["stages"]
    n = len(lock)
    return {"stages": n,
            "deps_per_stage": sum(len(s.get("deps", [])) for s in lock.values()) / n,
            "outs_per_stage": sum(len(s.get("outs", [])) for s in lock.values()) / n,
            "params_per_stage": sum(len(v) for s in lock.values() for v in s.get("params", {}).values()) / n}


def make_floor(where: Path, stages: int, deps: int, outs: int, params_yaml: Path) -> Path:
    """A DVC project of ``stages`` trivial stages, each with ``deps`` small code files and ``outs`` outputs, reading
    the ``env`` and ``grid`` sections of the pipeline's params.yaml; reproduced once, so the next repro is a no-op."""
    where.mkdir(parents=True)
    subprocess.run(["git", "init", "-q"], cwd=where, check=True)
    _dvc(["init", "-q"], where)
    _dvc(["config", "core.analytics", "false"], where)
    (where / "src").mkdir()
    for i in range(deps):
        (where / "src" / f"m{i}.py").write_text(f"x = {i}\n")
    shutil.copy(params_yaml, where / "params.yaml")
    doc = {"stages": {f"s{s}": {
        "cmd": " && ".join(f"mkdir -p out/s{s}/o{o} && echo {s} > out/s{s}/o{o}/f" for o in range(outs)),
        "deps": [f"src/m{i}.py" for i in range(deps)], "params": ["env", "grid"],
        "outs": [f"out/s{s}/o{o}" for o in range(outs)]} for s in range(stages)}}
    (where / "dvc.yaml").write_text(yaml.safe_dump(doc))
    _dvc(["repro", "-q"], where)
    return where


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", default=str(ROOT / "benchmarks/results/noop_repro.json"))
    ap.add_argument("--project", type=Path, default=ROOT,
                    help="the reproduced project to time (default this repository; a copy of the DAG on tiny params, "
                         "as benchmarks/noop_shapes.py builds, has the same shape without the full run's outputs)")
    args = ap.parse_args()
    project = args.project.resolve()
    if not (project / "dvc.lock").is_file():
        raise SystemExit(f"--project {project}: no dvc.lock there; reproduce the pipeline in it first")
    if _dvc(["status", "-q"], project).strip():
        raise SystemExit(f"the pipeline in {project} is not up to date (`dvc status`): reproduce it before timing a "
                         "no-op")
    shape = pipeline_shape(project)
    deps, outs = round(shape["deps_per_stage"]), max(1, round(shape["outs_per_stage"]))
    variants = {"pipeline": project}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        params_yaml = project / "params.yaml"
        variants["floor"] = make_floor(tmp / "floor", shape["stages"], deps, outs, params_yaml)
        variants["floor_half_deps"] = make_floor(tmp / "half_deps", shape["stages"], deps // 2, outs, params_yaml)
        variants["floor_half_stages"] = make_floor(tmp / "half_stages", shape["stages"] // 2, deps, outs,
                                                   params_yaml)
        times: dict[str, list[float]] = {k: [] for k in variants}
        for _ in range(args.repeats):
            for name, cwd in variants.items():
                times[name].append(_timed_noop(cwd))
    med = {k: statistics.median(v) for k, v in times.items()}
    result = {
        "benchmark": "no-op dvc repro: the pipeline against trivial DVC projects of its shape (DVC's own floor)",
        "project": "this repository" if project == ROOT else str(project),
        "shape": shape, "floor_deps_per_stage": deps, "floor_outs_per_stage": outs, "repeats": args.repeats,
        "times_s": times, "median_s": med,
        "pipeline_over_floor": med["pipeline"] / med["floor"],
        "per_stage_floor_s": (med["floor"] - med["floor_half_stages"]) / (shape["stages"] - shape["stages"] // 2),
        "per_dep_per_stage_floor_s": (med["floor"] - med["floor_half_deps"]) / (shape["stages"] * (deps - deps // 2)),
        "machine": platform.platform(), "dvc": _dvc(["--version"], ROOT).strip()}
    Path(args.out).write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps({k: result[k] for k in ("median_s", "pipeline_over_floor", "per_stage_floor_s",
                                              "per_dep_per_stage_floor_s")}, indent=2))


if __name__ == "__main__":
    main()
