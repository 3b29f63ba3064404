"""The expert job: train (or resume) the SAC expert of one pairing (the first half of the pipeline)."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from lfdt import mlflow_runs, stage
from lfdt.box_push_jobs.common import numeric
from lfdt.config import Params
from lfdt.nets import torch_device
from lfdt.parallel import Progress
from lfdt.tasks.box_push import experts


@dataclass(frozen=True)
class ExpertJob:
    """One pairing's expert, with the folders its job writes (from the stage's command line)."""

    pairing: str
    params: Params
    """params.yaml as the stage validated it."""
    experts_dir: Path
    """The experts, one folder per pairing."""
    checkpoints_dir: Path
    """Resumable training checkpoints, one folder per pairing (cleared when the expert is saved)."""
    reports_dir: Path
    """The training reports and learning curves: ``<pairing>_train.json``, ``<pairing>_curve.csv``."""


def expert_job(job: ExpertJob, progress: Progress | None = None) -> dict:
    """Train (or resume) the SAC expert of one pairing, evaluate it on fresh seeds, save it."""
    pairing = job.pairing
    t0 = time.perf_counter()
    p = job.params
    cfg, env_cfg, demos_cfg = p.experts, p.env, p.demos
    out = job.experts_dir / pairing
    device = torch_device(p.device)
    with mlflow_runs.stage_run("train_experts", {"env": env_cfg.model_dump(), "experts": cfg.model_dump(),
                                              **experts.protocol_doc(demos_cfg), "device": p.device},
                               tags={"pairing": pairing, "seed": cfg.seed, "protocol": demos_cfg.protocol},
                               run_name=f"{pairing} train_experts") as run:
        model, stats = experts.train_expert(pairing, env_cfg, cfg, demos_cfg, job.checkpoints_dir / pairing,
                                            log=run.metrics, progress=progress, device=device)
        ev = experts.evaluate_expert(model, pairing, env_cfg, demos_cfg, cfg.eval_episodes, cfg.seed)
        curve = stats.pop("curve")
        summary = {"pairing": pairing, "protocol": demos_cfg.protocol, **ev, **stats,
                   "job_wall_s": time.perf_counter() - t0, "mlflow_run_id": run.run_id}
        # the resolved config beside the model holds no wall times or speeds, so an identical rerun writes the same
        # model folder and what is downstream of it does not rerun (those go to runs/experts/)
        measured = {k: v for k, v in stats.items() if not stage.is_bookkeeping(k)}
        experts.save_expert(model, out, pairing, env_cfg, cfg, demos_cfg, {"evaluation": ev, "training": measured})
        stage.write_report(job.reports_dir / f"{pairing}_train.json", summary)
        stage.write_csv(job.reports_dir / f"{pairing}_curve.csv",
                        [{"timesteps": c["timesteps"], "success_rate": c["train/success_rate_last100"],
                          "episode_return": c["train/episode_return_last100"]} for c in curve])
        run.metrics({f"eval/{k}": v for k, v in numeric(ev).items()})
        run.metrics(numeric(stats))
        run.artifact(out / "config.json")
        run.artifact(job.reports_dir / f"{pairing}_curve.csv")
        experts.Checkpoints(job.checkpoints_dir / pairing, "").clear()
    return summary
