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
