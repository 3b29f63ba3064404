"""The evaluation job: one configuration's policy from the evaluation start states."""

from __future__ import annotations

import time

import numpy as np
import torch

from lfdt import bc, evaluation, mlflow_runs, stage
from lfdt.jobs.common import Config, numeric
from lfdt.parallel import Progress


def evaluate_job(cfg: Config, progress: Progress | None = None) -> dict:
    """Run one configuration's policy from the evaluation start states (the same for every configuration)."""
    t0 = time.perf_counter()
    p = stage.params(cfg.params)
    ecfg = p.evaluation
    torch.set_num_threads(1)
    policy, _ = bc.BCPolicy.load(cfg.dir(cfg.policies_dir))
    tags = {**cfg.tags(), "domain": "Y"}
    with mlflow_runs.stage_run("evaluate", {"evaluation": ecfg.model_dump(), **cfg.tags()}, tags=tags,
                            run_name=f"{cfg.name} evaluate") as run:
        trials = evaluation.run_trials(policy, p.env, ecfg.trials, ecfg.videos, cfg.dir(cfg.videos_dir),
                                       ecfg.video_size, progress=progress, purpose=ecfg.start_states)
        ok = np.array([t["success"] for t in trials])
        summary = {**cfg.tags(), "start_states": ecfg.start_states, "successes": int(ok.sum()),
                   "trials": len(trials),
                   "success_rate": float(ok.mean()),
                   f"success_rate_first{evaluation.PAPER_TRIALS}": float(ok[:evaluation.PAPER_TRIALS].mean()),
                   "mean_final_box_distance_m": float(np.mean([t["final_box_distance_m"] for t in trials])),
                   "mean_final_yaw_error_rad": float(np.mean([t["final_yaw_error_rad"] for t in trials])),
                   "job_wall_s": time.perf_counter() - t0, "mlflow_run_id": run.run_id}
        run.metrics(numeric(summary))
        if ecfg.videos:
            run.artifact(cfg.dir(cfg.videos_dir), "videos")
    rows = [{"method": cfg.method, "demos": cfg.demos, "seed": cfg.seed, "start_states": ecfg.start_states,
             "trial": t["trial"], "start_seed": t["seed"],
             "success": bool(t["success"]), "steps": t["steps"], "final_box_distance_m": t["final_box_distance_m"],
             "final_yaw_error_rad": t["final_yaw_error_rad"]} for t in trials]
    return {"metrics": summary, "trials": rows}
