"""The evaluation job: the policies of a group of seeds of one configuration from the evaluation start states, all
trials stepped in lockstep with one policy call per control step."""

from __future__ import annotations

import contextlib
import time
from pathlib import Path

import numpy as np
import torch

from lfdt import bc, evaluation, mlflow_runs
from lfdt.box_push_jobs.common import LAYOUT, Config, numeric
from lfdt.config import EnvConfig
from lfdt.parallel import Progress
from lfdt.tasks.box_push.env import BoxPushModel
from lfdt.tasks.box_push.task import TASK as BOX_PUSH_TASK


def check_policies(cfgs: list[Config]) -> None:
    """Load every seed's policy once, in the stage's process, before any trial: a missing or damaged one stops the
    stage naming its file (:class:`lfdt.nets.ModelFileError`) before a worker starts evaluating the others."""
    for cfg in cfgs:
        bc.BCPolicy.load(cfg.dir(cfg.policies_dir), LAYOUT, BOX_PUSH_TASK.action_bounds)


def evaluate_job(cfgs: list[Config], progress: Progress | None = None) -> list[dict]:
    """Run the policies of a group of seeds from the evaluation start states (the same for every configuration).
    One result per seed, in order; a seed's trials do not depend on the others of its group."""
    t0 = time.perf_counter()
    p = cfgs[0].params
    ecfg = p.evaluation
    torch.set_num_threads(1)
    policies = [bc.BCPolicy.load(cfg.dir(cfg.policies_dir), LAYOUT, BOX_PUSH_TASK.action_bounds)[0] for cfg in cfgs]
    with contextlib.ExitStack() as runs_stack:
        runs = [runs_stack.enter_context(mlflow_runs.stage_run(
            "evaluate", {"evaluation": ecfg.model_dump(), **cfg.tags()}, tags={**cfg.tags(), "domain": "Y"},
            run_name=f"{cfg.name} evaluate")) for cfg in cfgs]
        all_trials = box_push_trials(bc.StackedPolicies(policies), len(policies), p.env, ecfg.trials, ecfg.videos,
                                     [cfg.dir(cfg.videos_dir) for cfg in cfgs], ecfg.video_size, progress=progress,
                                     purpose=ecfg.start_states)
        results = []
        for cfg, run, trials in zip(cfgs, runs, all_trials):
            ok = np.array([t["success"] for t in trials])
            path_ok = np.array([t["path_success"] for t in trials])
            summary = {**cfg.tags(), "start_states": ecfg.start_states, "successes": int(ok.sum()),
                       "trials": len(trials), "success_rate": float(ok.mean()),
                       "path_success_rate": float(path_ok.mean()),
                       f"success_rate_first{evaluation.PAPER_TRIALS}": float(ok[:evaluation.PAPER_TRIALS].mean()),
                       "mean_final_box_distance_m": float(np.mean([t["final_box_distance_m"] for t in trials])),
                       "mean_final_yaw_error_rad": float(np.mean([t["final_yaw_error_rad"] for t in trials])),
                       "job_wall_s": time.perf_counter() - t0, "mlflow_run_id": run.run_id}
            run.metrics(numeric(summary))
            if ecfg.videos:
                run.artifact(cfg.dir(cfg.videos_dir), "videos")
            rows = [{"method": cfg.method, "demos": cfg.demos, "seed": cfg.seed, "start_states": ecfg.start_states,
                     "trial": t["trial"], "start_seed": t["seed"], "success": bool(t["success"]),
                     "path_success": bool(t["path_success"]), "steps": t["steps"],
                     "max_abs_yaw_rad": t["max_abs_yaw_rad"], "final_box_distance_m": t["final_box_distance_m"],
                     "final_yaw_error_rad": t["final_yaw_error_rad"]}
                    for t in trials]
            results.append({"metrics": summary, "trials": rows})
    return results


def box_push_trials(act, policies: int, env_cfg: EnvConfig, trials: int, videos: int = 0,
                    video_dirs: list[Path] | None = None, video_size: int = 240, progress=None,
                    purpose: str = "evaluation") -> list[list[dict]]:
    """Run ``policies`` policies (``act``: observations ``(policies, trials, obs)`` -> actions) in the box push's Y
    from the fixed start states, in lockstep; per policy and trial the outcome, the first ``videos`` as mp4."""
    scene = BoxPushModel("Y", env_cfg)  # one compiled scene for every trial's environment

    def make_env(record: bool):
        if record:
            return BOX_PUSH_TASK.make_env("Y", env_cfg, "rgb_array", video_size)
        return BOX_PUSH_TASK.make_env("Y", env_cfg, scene=scene)

    results = evaluation.rollout_lockstep(act, make_env, policies, trials, videos, video_dirs, progress, purpose)
    for per_policy in results:
        for r in per_policy:
            info = r.pop("final_info")
            r.update({"path_success": bool(r["success"] and info["is_path_success"]),
                      "max_abs_yaw_rad": info["max_abs_yaw"],
                      "final_box_distance_m": info["box_distance"], "final_yaw_error_rad": abs(info["box_yaw"])})
    return results
