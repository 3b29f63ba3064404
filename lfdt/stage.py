"""Helpers shared by the thin stage scripts in ``stages/``: params, outputs, progress bars, errors."""

from __future__ import annotations

import csv
import json
import os
import sys
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

from tqdm import tqdm

from lfdt.config import Params, ParamsError, load_params
from lfdt.errors import StageError
from lfdt.files import temp_path


def params(path: str | Path = "params.yaml") -> Params:
    """Load and validate params.yaml (every stage does this before any compute)."""
    return load_params(path)


def main(fn: Callable[[], None]) -> None:
    """Run a stage's main; a params problem or a :class:`~lfdt.errors.StageError` (a wrong data file, an unreachable
    tracking server, a diverged training) exits 2 with its message; anything else raises (non-zero exit)."""
    try:
        fn()
    except (ParamsError, StageError) as err:
        print(f"error: {err}", file=sys.stderr)
        sys.exit(2)


def write_json(path: str | Path, obj: Any) -> Path:
    """Write JSON atomically (small metrics files)."""
    path = Path(path)
    tmp = temp_path(path)
    tmp.write_text(json.dumps(obj, indent=2, sort_keys=False) + "\n")
    os.replace(tmp, path)
    return path


REPORTS = Path("reports")
RUNS = Path("runs")


def is_bookkeeping(key: str) -> bool:
    """A key that describes how a run went rather than what it measured: MLflow ids, wall times, speeds. Two identical
    runs differ in these, so they stay out of the metrics files (``reports/``) and go to ``runs/``."""
    return key.startswith("mlflow_") or "wall" in key or key.endswith("_per_s")


def runs_path(metrics_path: str | Path) -> Path:
    """Where the bookkeeping of a metrics file lives: ``[root/]reports/a/b.json`` -> ``[root/]runs/a/b.json``."""
    path = Path(metrics_path)
    parts = path.parts
    if REPORTS.name not in parts[:-1]:
        raise StageError(f"{path}: a metrics file must lie under {REPORTS}/ (its bookkeeping goes to {RUNS}/)")
    i = max(k for k, part in enumerate(parts[:-1]) if part == REPORTS.name)  # the last, as in reports/x/reports/
    return Path(*parts[:i], RUNS.name, *parts[i + 1:])


def _split(obj: Any) -> tuple[Any, dict]:
    """(measured, bookkeeping) of a report; dicts are split key by key at every depth, anything else is measured."""
    if not isinstance(obj, Mapping):
        return obj, {}
    measured, books = {}, {}
    for k, v in obj.items():
        if is_bookkeeping(str(k)):
            books[k] = v
            continue
        m, b = _split(v)
        measured[k] = m
        if b:
            books[k] = b
    return measured, books


def write_report(path: str | Path, report: Mapping[str, Any]) -> Path:
    """Write a stage's report: its measured results to ``path`` (a DVC metric, identical when a run is repeated), its
    bookkeeping (:func:`is_bookkeeping`) to :func:`runs_path` (a cached DVC output that is not a metric)."""
    measured, books = _split(report)
    rp = runs_path(path)
    rp.parent.mkdir(parents=True, exist_ok=True)
    write_json(rp, books)
    return write_json(path, measured)


def _merge(a: Any, b: Any) -> Any:
    if isinstance(a, dict) and isinstance(b, dict):
        return {**a, **{k: _merge(a.get(k), v) for k, v in b.items()}}
    return b


def read_report(path: str | Path) -> dict:
    """A report written by :func:`write_report`, its bookkeeping merged back in; a missing file of the two is an
    error naming it (run the stage that writes it)."""
    path = Path(path)
    parts = []
    for f in (path, runs_path(path)):
        try:
            parts.append(json.loads(f.read_text()))
        except FileNotFoundError:
            raise StageError(f"{f} is missing: run the stage that writes it (`dvc repro`)") from None
        except json.JSONDecodeError as err:
            raise StageError(f"{f} is not valid JSON ({err})") from None
    return _merge(*parts)


def run_ids(bookkeeping: Mapping[str, Any]) -> list[str]:
    """The MLflow run ids a stage's bookkeeping (a ``runs/`` file) names: the stage's own, then each seed's."""
    ids = [bookkeeping.get("mlflow_run_id")]
    ids += [s.get("mlflow_run_id") for s in bookkeeping.get("seeds", {}).values()]
    return [i for i in ids if i]


def write_csv(path: str | Path, rows: Iterable[Mapping[str, Any]]) -> Path:
    """Write a list of dicts as CSV atomically (DVC plots). The columns are the union of the rows' keys in the order
    they first appear; a row without a column leaves its cell empty (e.g. a curve's rows logged at different
    intervals)."""
    rows = list(rows)
    path = Path(path)
    tmp = temp_path(path)
    with open(tmp, "w", newline="") as fh:
        if rows:
            w = csv.DictWriter(fh, fieldnames=list(dict.fromkeys(k for r in rows for k in r)), restval="")
            w.writeheader()
            w.writerows(rows)
    os.replace(tmp, path)
    return path


def wall_since_start() -> float:
    """Seconds since this process started (imports included): a stage's own wall time."""
    import time

    import psutil

    return time.time() - psutil.Process().create_time()


def matrix_arguments(description: str, methods) -> tuple[str, int, str, Params]:
    """``--method`` and ``--demos`` of one matrix instance (its seeds come from ``grid.seeds``) and ``--params``;
    returns the method, the demonstration count, the params path and the validated params."""
    import argparse

    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--method", required=True, choices=sorted(methods))
    ap.add_argument("--demos", required=True, type=int)
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    p = params(args.params)
    if args.demos > p.demos.per_pairing:
        raise ParamsError(f"--demos {args.demos} is more than demos.per_pairing = {p.demos.per_pairing}")
    return args.method, args.demos, args.params, p


def group_report(results: list[dict], wall_key: str = "stage_wall_s") -> dict:
    """The metrics of a matrix instance's jobs, keyed by seed, with the stage's own wall time."""
    first = results[0]["metrics"]
    return {"method": first["method"], "demos": first["demos"],
            "seeds": {str(r["metrics"]["seed"]): r["metrics"] for r in results}, wall_key: wall_since_start()}


def task_arguments(description: str, tasks) -> tuple[str, Params]:
    """Parse ``--task`` and ``--params`` of a twin stage; returns the task and the validated params."""
    import argparse

    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--task", required=True, choices=tasks)
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    return args.task, params(args.params)


def config_name(method: str, demos: int, seed: int) -> str:
    """Name of one (method, demos, seed) configuration in file and run names."""
    return f"{method}-d{demos}-s{seed}"


def progress(total: int | None, desc: str, unit: str = "it") -> tqdm:
    """A progress bar on stderr."""
    return tqdm(total=total, desc=desc, unit=unit, unit_scale=True, mininterval=1.0, dynamic_ncols=True,
                file=sys.stderr)
