"""The re-execution job (lfdt_track): execute one configuration's translated demonstrations in Y."""

from __future__ import annotations

import dataclasses
import time

from lfdt import data, methods, mlflow_runs
from lfdt.box_push_jobs.common import DATA_FILE, DYNAMICS_FILE, LAYOUT, Config, numeric
from lfdt.dynamics import load_models
from lfdt.parallel import Progress
from lfdt.tasks.box_push import columns as box_columns
from lfdt.tasks.box_push import reexecute
from lfdt.translation.apply import translated_table


def track_job(cfg: Config, progress: Progress | None = None) -> dict:
    """Re-execute the translated demonstrations of the method's translator in Y; keep the successful ones."""
    t0 = time.perf_counter()
    p = cfg.params
    m = methods.get(cfg.method)
    source = dataclasses.replace(cfg, method=m.translator)
    df = data.read_transitions(source.dir(cfg.bc_data_dir) / DATA_FILE["translated"], kind="translated", domain="Y")
    dyn = load_models(cfg.dynamics_dir / DYNAMICS_FILE) if p.track.controller == "inverse" else None
    with mlflow_runs.stage_run("track_demos", {"track": p.track.model_dump(), **cfg.tags()}, tags=cfg.tags(),
                            run_name=f"{cfg.name} track_demos") as run:
        out, stats = reexecute.execute(df, p.env, p.track, dyn,
                                       progress=(lambda: progress.update(1)) if progress is not None else None)
        table = translated_table(out, {
            "kind": "executed", "domain": "Y", **cfg.tags(), "track": p.track.model_dump(),
            "source": str(source.dir(cfg.bc_data_dir) / DATA_FILE["translated"]), "layout": box_columns.describe(),
            "description": "translated demonstrations re-executed in Y in closed loop; only the executions that "
                           "solved the task; states and actions as really visited and sent"}, LAYOUT)
        data.write_table(table, cfg.dir(cfg.bc_data_dir) / DATA_FILE["executed"])
        metrics = {**cfg.tags(), **stats, "job_wall_s": time.perf_counter() - t0, "mlflow_run_id": run.run_id}
        run.metrics(numeric(metrics))
    return {"metrics": metrics}
