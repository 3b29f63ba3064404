"""The evaluation job: one configuration's policy from the evaluation start states."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch

from lfdt import bc, evaluation, mlflow_runs, stage
from lfdt.config import EnvConfig
from lfdt.jobs.common import TASK, Config, numeric
from lfdt.parallel import Progress
from lfdt.tasks.box_push.env import BoxPushEnv
from lfdt.tasks.box_push.task import TASK as BOX_PUSH_TASK


def evaluate_job(cfg: Config, progress: Progress | None = None) -> dict:
    """Run one configuration's policy from the evaluation start states (the same for every configuration)."""
    t0 = time.perf_counter()
    p = stage.params(cfg.params)
    ecfg = p.evaluation
    torch.set_num_threads(1)
    policy, _ = bc.BCPolicy.load(cfg.dir(cfg.policies_dir), TASK)
    tags = {**cfg.tags(), "domain": "Y"}
    with mlflow_runs.stage_run("evaluate", {"evaluation": ecfg.model_dump(), **cfg.tags()}, tags=tags,
                            run_name=f"{cfg.name} evaluate") as run:
        trials = box_push_trials(policy, p.env, ecfg.trials, ecfg.videos, cfg.dir(cfg.videos_dir), ecfg.video_size,
                                 progress=progress, purpose=ecfg.start_states)
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


def box_push_trials(policy: Callable[[np.ndarray], np.ndarray], env_cfg: EnvConfig, trials: int, videos: int = 0,
                    video_dir: Path | None = None, video_size: int = 240, progress=None,
                    purpose: str = "evaluation") -> list[dict]:
    """Run a policy in the box push's Y from the fixed start states; per-trial outcome, first ``videos`` as mp4."""
    def make_env(record: bool) -> BoxPushEnv:
        return BOX_PUSH_TASK.make_env("Y", env_cfg, "rgb_array" if record else None, video_size)

    results = evaluation.rollout_trials(policy, make_env, trials, videos, video_dir, progress, purpose)
    for r in results:
        info = r.pop("final_info")
        r.update({"final_box_distance_m": info["box_distance"], "final_yaw_error_rad": abs(info["box_yaw"])})
    return results
