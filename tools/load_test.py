"""Load test of the tracking store: several sweeps and the MLflow UI at once on one machine, then a count of what
landed. Nothing may be lost: every run, every param and every metric row that was logged is in the store, once.

Each sweep is a process shaped like ``python -m lfdt.sweep``'s traffic on the store: a parent run, then for each of
its points ``--workers`` stage processes at once, each a stage run of the project's own tracking code
(:func:`lfdt.mlflow_runs.stage_run`: the experiment lookup under its file lock, the stray-run check, tags, params, a
metric curve through the buffered :class:`~lfdt.mlflow_runs.Tracker`), and at the end the children adopted by the
parent (:func:`~lfdt.mlflow_runs.adopt_children`). There is no training: only the store is loaded. Meanwhile the
MLflow UI (``mlflow ui`` on 127.0.0.1, as ``make mlflow-ui`` starts it) serves the requests its runs table and
metric charts make, as fast as it answers. With ``--store server`` the stages log through that server instead of
writing the database themselves, as when a team shares one.

The counts are made afterwards on the database itself (sqlite), not through MLflow. Every process is started in a
session of its own and stopped by process group, also when the test fails; the whole test is bounded by
``--timeout``.

    python tools/load_test.py                    # 4 sweeps on each store, reports/load.json (README: make docs)
    python tools/load_test.py --store server --sweeps 2 --points 1 --steps 50 --out /tmp/load.json
"""

from __future__ import annotations

import argparse
import json
import os
import random
import sqlite3
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request
from datetime import date
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import services  # noqa: E402 - the tests' helpers for servers started on 127.0.0.1 and stopped by process group

EXPERIMENT = "load-test"
PARENT = "sweep {sweep}"
CHILD = "sweep {sweep} point {point} worker {worker}"


def _value(sweep: int, point: int, worker: int, metric: int, step: int) -> float:
    """The value every row carries: a function of where it was logged, so that a row written into the wrong run or
    the wrong step shows in the count."""
    return float(((sweep * 100 + point) * 10 + worker) * 1000 + metric) + step / 1e4


# ---- the processes a load test starts (this file with --role) ----

def _writer(sweep: int, point: int, worker: int, metrics: int, steps: int) -> None:
    """One stage process of a sweep point: one stage run, ``metrics`` curves of ``steps`` steps each."""
    from lfdt import mlflow_runs

    name = CHILD.format(sweep=sweep, point=point, worker=worker)
    params = {"sweep": sweep, "point": point, "worker": worker, "grid": {"seeds": [worker], "workers": 2}}
    with mlflow_runs.stage_run("load_writer", params, run_name=name) as run:
        for step in range(steps):
            run.metrics({f"m{m}": _value(sweep, point, worker, m, step) for m in range(metrics)}, step=step)
    print(run.run_id, flush=True)


def _sweep(sweep: int, points: int, workers: int, metrics: int, steps: int) -> None:
    """One sweep: its parent run, then each point's ``workers`` writers at once, then the children adopted."""
    from lfdt import mlflow_runs

    children: list[str] = []
    with mlflow_runs.stage_run("load_sweep", {"sweep": sweep, "points": points}, run_name=PARENT.format(sweep=sweep)) \
            as parent:
        for point in range(points):
            procs = [subprocess.Popen([sys.executable, __file__, "--role", "writer", "--sweep", str(sweep),
                                       "--point", str(point), "--worker", str(w), "--metrics", str(metrics),
                                       "--steps", str(steps)], stdout=subprocess.PIPE, text=True)
                     for w in range(workers)]
            for w, proc in enumerate(procs):
                out, _ = proc.communicate()
                if proc.returncode != 0:
                    raise SystemExit(f"sweep {sweep} point {point} worker {w} exited with {proc.returncode}")
                children.append(out.split()[-1])
            parent.metrics({"points_done": point + 1}, step=point)
        mlflow_runs.adopt_children(parent.run_id, children)


# ---- the test ----

class UiClient(threading.Thread):
    """Requests of the MLflow UI's runs table and charts, one after another until stopped; counts errors."""

    def __init__(self, url: str, experiment_id: str) -> None:
        super().__init__(daemon=True)
        self.url, self.experiment_id = url, experiment_id
        self.latencies: list[float] = []
        self.errors: list[str] = []
        self.done = threading.Event()

    def _call(self, path: str, body: dict | None = None) -> dict:
        req = urllib.request.Request(self.url + path, data=json.dumps(body).encode() if body is not None else None,
                                     headers={"Content-Type": "application/json"})
        t = time.perf_counter()
        with urllib.request.urlopen(req, timeout=30) as resp:
            doc = json.loads(resp.read() or b"{}")
        self.latencies.append(time.perf_counter() - t)
        return doc

    def run(self) -> None:
        rng = random.Random(0)
        while not self.done.is_set():
            try:
                runs = self._call("/api/2.0/mlflow/runs/search", {
                    "experiment_ids": [self.experiment_id], "max_results": 100,
                    "order_by": ["attributes.start_time DESC"]}).get("runs", [])
                if runs:
                    run = rng.choice(runs)["info"]["run_id"]
                    self._call(f"/api/2.0/mlflow/metrics/get-history?run_id={run}&metric_key=m0&max_results=25000")
            except Exception as err:  # noqa: BLE001 - every failed request is counted and reported, not raised
                self.errors.append(f"{type(err).__name__}: {err}")
                time.sleep(0.2)


def count(db: Path, sweeps: int, points: int, workers: int, metrics: int, steps: int) -> dict:
    """What the store holds, against what was logged: runs, their status, params, metric rows (each key's steps
    0..steps-1 once, each value the one that was logged there) and parent tags."""
    with sqlite3.connect(db) as con:
        exp = con.execute("SELECT experiment_id FROM experiments WHERE name = ?", (EXPERIMENT,)).fetchone()[0]
        runs = {}
        for uuid, name, status in con.execute("SELECT run_uuid, name, status FROM runs WHERE experiment_id = ?",
                                              (exp,)):
            runs.setdefault(name, []).append((uuid, status))
        problems: list[str] = []
        rows_found = 0
        parents = {s: runs.get(PARENT.format(sweep=s), []) for s in range(sweeps)}
        for s in range(sweeps):
            if [st for _, st in parents[s]] != ["FINISHED"]:
                problems.append(f"{PARENT.format(sweep=s)}: runs {parents[s]}")
            for p in range(points):
                for w in range(workers):
                    name = CHILD.format(sweep=s, point=p, worker=w)
                    found = runs.get(name, [])
                    if [st for _, st in found] != ["FINISHED"]:
                        problems.append(f"{name}: runs {found}")
                        continue
                    uuid = found[0][0]
                    rows = con.execute("SELECT key, step, value FROM metrics WHERE run_uuid = ?", (uuid,)).fetchall()
                    rows_found += len(rows)
                    want = {(f"m{m}", t, _value(s, p, w, m, t)) for m in range(metrics) for t in range(steps)}
                    got = [(k, t, v) for k, t, v in rows]
                    if len(got) != len(want) or set(got) != want:
                        problems.append(f"{name}: {len(got)} metric rows, {len(set(got) & want)} of the "
                                        f"{len(want)} logged")
                    nparams = con.execute("SELECT count(*) FROM params WHERE run_uuid = ?", (uuid,)).fetchone()[0]
                    if nparams != 5:
                        problems.append(f"{name}: {nparams} params, 5 logged")
                    tag = con.execute("SELECT value FROM tags WHERE run_uuid = ? AND key = 'mlflow.parentRunId'",
                                      (uuid,)).fetchone()
                    if parents[s] and (tag is None or tag[0] != parents[s][0][0]):
                        problems.append(f"{name}: not a child of its sweep's run")
        expected = {PARENT.format(sweep=s) for s in range(sweeps)} | {
            CHILD.format(sweep=s, point=p, worker=w) for s in range(sweeps) for p in range(points)
            for w in range(workers)}
        problems += [f"{name}: {len(found)} runs nobody logged" for name, found in sorted(runs.items())
                     if name not in expected]
    return {"runs_logged": sweeps * (1 + points * workers), "runs_found": sum(len(v) for v in runs.values()),
            "metric_rows_logged": sweeps * points * workers * metrics * steps, "metric_rows_found": rows_found,
            "problems": problems}


STORES = {"sqlite": "the stages write the sqlite database themselves while `mlflow ui` reads it (one machine)",
          "server": "the stages log through the MLflow server that also serves the UI (a team's shared server)",
          "mixed": "every other sweep logs through that server, the rest write the database (both at once)"}
"""How the sweeps reach the store."""


def load_test(sweeps: int = 4, points: int = 3, workers: int = 2, metrics: int = 8, steps: int = 500,
              timeout: float = 900, workdir: Path | None = None, store: str = "sqlite") -> dict:
    """Run the load test in ``workdir`` (a new temporary folder by default) with the sweeps reaching the store as
    ``store`` says (:data:`STORES`); returns its report (``problems`` empty when nothing was lost)."""
    from lfdt import numerics

    if store not in STORES:
        raise ValueError(f"store {store!r}: one of {sorted(STORES)}")
    workdir = Path(workdir or tempfile.mkdtemp(prefix="lfdt-load-"))
    workdir.mkdir(parents=True, exist_ok=True)
    db = workdir / "mlflow.db"
    port = services.free_port()
    url = f"http://127.0.0.1:{port}"
    env = {**os.environ, "MLFLOW_TRACKING_URI": f"sqlite:///{db}", "LFDT_MLFLOW_EXPERIMENT": EXPERIMENT,
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep)}
    # the store and the experiment exist before the UI opens the database (as after a first `dvc repro`)
    subprocess.run([sys.executable, "-c", "from lfdt import mlflow_runs; print(mlflow_runs.experiment_id())"],
                   env=env, check=True, capture_output=True, timeout=300)
    with sqlite3.connect(db) as con:
        exp_id = con.execute("SELECT experiment_id FROM experiments WHERE name = ?", (EXPERIMENT,)).fetchone()[0]
    through_server = {s for s in range(sweeps) if store == "server" or (store == "mixed" and s % 2)}
    log = workdir / "mlflow-ui.log"
    procs: list[subprocess.Popen] = []
    with open(log, "ab") as fh:
        procs.append(subprocess.Popen([str(Path(sys.executable).parent / "mlflow"),
                                       "server" if through_server else "ui", "--backend-store-uri",
                                       f"sqlite:///{db}", "--host", "127.0.0.1", "--port", str(port)],
                                      stdout=fh, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                      start_new_session=True, env=env))
    ui = UiClient(url, str(exp_id))
    failed: list[str] = []
    try:
        services.wait_for(lambda: urllib.request.urlopen(f"{url}/health", timeout=2).close() is None,
                          f"the MLflow UI at {url}", procs[0], timeout=120, log=log)
        ui.start()
        start = time.perf_counter()
        sweeps_procs = []
        for s in range(sweeps):
            out = open(workdir / f"sweep{s}.log", "wb")  # noqa: SIM115 - the child holds it until it ends
            sweeps_procs.append(subprocess.Popen(
                [sys.executable, __file__, "--role", "sweep", "--sweep", str(s), "--points", str(points),
                 "--workers", str(workers), "--metrics", str(metrics), "--steps", str(steps)],
                stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, start_new_session=True,
                env={**env, "MLFLOW_TRACKING_URI": url} if s in through_server else env))
        procs += sweeps_procs
        deadline = time.monotonic() + timeout
        for s, p in enumerate(sweeps_procs):
            try:
                rc = p.wait(timeout=max(1.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                failed.append(f"sweep {s}: still running after {timeout:.0f} s")
                continue
            if rc != 0:
                tail = (workdir / f"sweep{s}.log").read_text(errors="replace")[-1500:]
                failed.append(f"sweep {s} exited with {rc}:\n{tail}")
        wall = time.perf_counter() - start
    finally:
        ui.done.set()
        ui.join(timeout=60)
        services.stop_all(procs)
    report = count(db, sweeps, points, workers, metrics, steps)
    lat = sorted(ui.latencies)
    info = numerics.describe()
    report = {
        "store": store, "how": STORES[store], "sweeps": sweeps, "points_per_sweep": points,
        "workers_per_point": workers, "metrics_per_run": metrics,
        "steps_per_metric": steps, **report, "problems": failed + report["problems"],
        "wall_s": round(wall, 1), "metric_rows_per_s": round(report["metric_rows_found"] / wall, 1),
        "ui_requests": len(lat), "ui_errors": len(ui.errors), "ui_error_examples": ui.errors[:3],
        "ui_p50_ms": round(1000 * statistics.median(lat), 1) if lat else None,
        "ui_p95_ms": round(1000 * lat[int(0.95 * (len(lat) - 1))], 1) if lat else None,
        "ui_max_ms": round(1000 * lat[-1], 1) if lat else None,
        "cpu_model": info["cpu_model"], "cores": os.cpu_count(), "date": date.today().isoformat(),
        "numerics": info["numerics"],
    }
    return report


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sweeps", type=int, default=4, help="sweeps at once")
    ap.add_argument("--points", type=int, default=3, help="points of each sweep, one after another")
    ap.add_argument("--workers", type=int, default=2, help="stage processes at once per point")
    ap.add_argument("--metrics", type=int, default=8, help="metric curves per stage run")
    ap.add_argument("--steps", type=int, default=500, help="steps of each curve")
    ap.add_argument("--timeout", type=float, default=900, help="seconds the sweeps may take in all")
    ap.add_argument("--store", choices=[*STORES, "both"], default="both",
                    help="how the sweeps reach the store: " + "; ".join(f"{k}: {v}" for k, v in STORES.items()))
    ap.add_argument("--out", type=Path, default=ROOT / "reports" / "load.json", help="where the report goes")
    ap.add_argument("--role", choices=["test", "sweep", "writer"], default="test", help=argparse.SUPPRESS)
    ap.add_argument("--sweep", type=int, default=0, help=argparse.SUPPRESS)
    ap.add_argument("--point", type=int, default=0, help=argparse.SUPPRESS)
    ap.add_argument("--worker", type=int, default=0, help=argparse.SUPPRESS)
    args = ap.parse_args()
    for name in ("sweeps", "points", "workers", "metrics", "steps"):
        if getattr(args, name) < 1:
            ap.error(f"--{name} must be at least 1, got {getattr(args, name)}")
    if args.role == "writer":
        _writer(args.sweep, args.point, args.worker, args.metrics, args.steps)
        return
    if args.role == "sweep":
        _sweep(args.sweep, args.points, args.workers, args.metrics, args.steps)
        return
    stores = ["sqlite", "server"] if args.store == "both" else [args.store]
    reports = {s: load_test(args.sweeps, args.points, args.workers, args.metrics, args.steps, args.timeout, store=s)
               for s in stores}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(reports, indent=2) + "\n")
    problems = [f"{s}: {p}" for s, r in reports.items() for p in r["problems"]]
    print(json.dumps({s: {k: v for k, v in r.items() if k != "problems"} for s, r in reports.items()}, indent=2))
    for p in problems:
        print("LOST:", p, file=sys.stderr)
    sys.exit(1 if problems else 0)

if __name__ == "__main__":
    main()
