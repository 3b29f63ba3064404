"""Helpers shared by the thin stage scripts in ``stages/``: arguments, params, the frame every stage runs in
(:func:`frame`: its MLflow run, progress bars, its report), outputs, errors."""

from __future__ import annotations

import argparse
import contextlib
import csv
import json
import numbers
import sys
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

from tqdm import tqdm

from lfdt import errors, inputs, mlflow_runs
from lfdt.config import Params, ParamsError, load_params
from lfdt.errors import StageError
from lfdt.files import write_atomic


def params(path: str | Path = "params.yaml") -> Params:
    """Load and validate params.yaml (every stage does this before any compute)."""
    return load_params(path)


INTERRUPTED = errors.INTERRUPTED
"""Exit code of a stage stopped by Ctrl-C (128 + SIGINT), as a shell reports it."""


def main(fn: Callable[[], None]) -> None:
    """Run a stage's main; a params problem or a :class:`~lfdt.errors.StageError` (a wrong data file, an unreachable
    tracking server, a diverged training) exits 2 with its message, as does an OSError (a missing input, a full disk,
    named by :func:`lfdt.inputs.os_error_message`); Ctrl-C exits :data:`INTERRUPTED` with one line; anything else
    raises (non-zero exit): :func:`lfdt.inputs.one_line_errors`.

    The stage ends within a second of the `dvc repro` that started it (:func:`lfdt.lifeline.watch`; its workers end
    with it), and holds a lock on its command line in this workspace while it runs, so that a rerun never writes
    the same outputs beside a stage still running."""
    from lfdt import lifeline

    lifeline.watch()

    def body() -> int:
        with lifeline.stage_lock(f"{Path.cwd()}: {' '.join(sys.argv)}", lifeline.LOCK_DIR):
            fn()
        return 0

    code = inputs.one_line_errors(body, "the stage's outputs are incomplete; `dvc repro` reruns it",
                                  refused=(ParamsError,))
    if code:
        sys.exit(code)


def write_json(path: str | Path, obj: Any) -> Path:
    """Write JSON atomically (small metrics files)."""
    text = json.dumps(obj, indent=2, sort_keys=False) + "\n"
    return write_atomic(path, lambda tmp: tmp.write_text(text))


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

    def write(tmp: Path) -> None:
        with open(tmp, "w", newline="") as fh:
            if rows:
                w = csv.DictWriter(fh, fieldnames=list(dict.fromkeys(k for r in rows for k in r)), restval="")
                w.writeheader()
                w.writerows(rows)

    return write_atomic(path, write)


def wall_since_start() -> float:
    """Seconds since this process started (imports included): a stage's own wall time."""
    import time

    import psutil

    return time.time() - psutil.Process().create_time()


def parser(description: str, paths: Mapping[str, str] | None = None) -> argparse.ArgumentParser:
    """A stage's argument parser: ``--params`` and, for each entry of ``paths``, a required ``--<name>`` (a path
    from dvc.yaml's ``vars``, given on the stage's command line) with its help text."""
    ap = inputs.ArgumentParser(description=description)
    ap.add_argument("--params", default="params.yaml")
    for name, help_text in (paths or {}).items():
        ap.add_argument(f"--{name}", required=True, type=Path, metavar="PATH", help=help_text)
    return ap


def matrix_arguments(description: str, methods, paths: Mapping[str, str]) -> tuple[argparse.Namespace, Params]:
    """The arguments of one matrix instance: ``--method`` and ``--demos`` (its seeds come from ``grid.seeds``),
    ``--params`` and the stage's ``paths`` (:func:`parser`); returns them and the validated params."""
    ap = parser(description, paths)
    ap.add_argument("--method", required=True, choices=sorted(methods))
    ap.add_argument("--demos", required=True, type=int)
    args = ap.parse_args()
    p = params(args.params)
    if args.demos > p.demos.per_pairing:
        raise ParamsError(f"--demos {args.demos} is more than demos.per_pairing = {p.demos.per_pairing}")
    return args, p


def group_report(results: list[dict]) -> dict:
    """The metrics of a matrix instance's jobs, keyed by seed (:func:`frame` adds the stage's wall time)."""
    first = results[0]["metrics"]
    return {"method": first["method"], "demos": first["demos"],
            "seeds": {str(r["metrics"]["seed"]): r["metrics"] for r in results}}


def task_arguments(description: str, tasks, paths: Mapping[str, str]) -> tuple[argparse.Namespace, Params]:
    """The arguments of a twin stage: ``--task``, ``--params`` and the stage's ``paths`` (:func:`parser`); returns
    them and the validated params."""
    ap = parser(description, paths)
    ap.add_argument("--task", required=True, choices=tasks)
    args = ap.parse_args()
    return args, params(args.params)


def config_name(method: str, demos: int, seed: int) -> str:
    """Name of one (method, demos, seed) configuration in file and run names."""
    return f"{method}-d{demos}-s{seed}"


def progress(total: int | None, desc: str, unit: str = "it") -> tqdm:
    """A progress bar on stderr."""
    return tqdm(total=total, desc=desc, unit=unit, unit_scale=True, mininterval=1.0, dynamic_ncols=True,
                file=sys.stderr)


def numeric(values: Mapping[str, Any]) -> dict[str, float]:
    """The real-number entries of a dict (Python's or numpy's), what MLflow takes as metrics; booleans are flags, not
    measurements."""
    return {k: v for k, v in values.items() if isinstance(v, numbers.Real) and not isinstance(v, bool)}


class Frame:
    """What a stage's body works with inside :func:`frame`: its MLflow run (None in a stage whose jobs open their
    own), its progress bars and the report it fills in."""

    def __init__(self, run: mlflow_runs.Tracker | None, bars: contextlib.ExitStack):
        self.run = run
        self.report: dict[str, Any] = {}
        """Written to the frame's report path when the body succeeds."""
        self._bars = bars

    def progress(self, total: int | None, desc: str, unit: str = "it") -> tqdm:
        """A progress bar on stderr (:func:`progress`), closed at the latest when the frame ends."""
        return self._bars.enter_context(progress(total, desc, unit))

    def metrics(self, values: Mapping[str, Any], step: int | None = None) -> None:
        """Log the numeric entries of ``values`` (:func:`numeric`) to the stage's run."""
        if self.run is None:
            raise StageError("this stage opened no MLflow run: its jobs log their own metrics")
        self.run.metrics(numeric(values), step)


@contextlib.contextmanager
def frame(report_path: str | Path | None, stage: str | None = None, run_params: Mapping[str, Any] | None = None, *,
          tags: Mapping[str, Any] | None = None, run_name: str | None = None) -> Iterator[Frame]:
    """The frame every stage runs in. With ``stage`` it opens the stage's MLflow run
    (:func:`lfdt.mlflow_runs.stage_run` with ``run_params``, ``tags`` and ``run_name``); matrix stages, whose jobs
    open their own runs, give none. When the body succeeds, :attr:`Frame.report` goes to ``report_path``
    (:func:`write_report`) with ``stage_wall_s`` (also logged to the run) and the run's ``mlflow_run_id``; when it
    raises, nothing is written and the run is marked FAILED. ``report_path`` None: the stage writes no report."""
    with contextlib.ExitStack() as stack:
        run = None
        if stage is not None:
            run = stack.enter_context(mlflow_runs.stage_run(stage, run_params or {}, tags=tags, run_name=run_name))
        with contextlib.ExitStack() as bars:
            f = Frame(run, bars)
            yield f
        wall = wall_since_start()
        extra: dict[str, Any] = {"stage_wall_s": wall}
        if run is not None:
            run.metrics({"stage_wall_s": wall})
            extra["mlflow_run_id"] = run.run_id
        if report_path is not None:
            write_report(report_path, {**f.report, **extra})
