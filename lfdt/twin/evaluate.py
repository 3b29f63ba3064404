"""Trials of the trained twin policies in the twin's domain Y (stage ``twin_evaluate``), and loading a trained policy
(also for ``python -m lfdt.robot deploy``)."""

from __future__ import annotations

from pathlib import Path

import torch

from lfdt import bc
from lfdt.config import TwinParams
from lfdt.tasks import registry
from lfdt.tasks.planar_env import TwinConfig, TwinEnv
from lfdt.twin import TWIN_METHODS
from lfdt.twin.common import SeedJob


def evaluate_policy(task: str, policy, trials: int, cfg: TwinConfig | None = None, purpose: str = "evaluation",
                    videos: int = 0, video_dir=None) -> list[dict]:
    """Trials of a policy in the twin's domain Y from fixed start states; per-trial success and the task's
    measures."""
    from lfdt.evaluation import rollout_trials

    def make_env(record: bool) -> TwinEnv:
        return registry.get(task).make_env("Y", cfg, "rgb_array" if record else None)

    results = rollout_trials(policy, make_env, trials, videos, video_dir, purpose=purpose)
    for r in results:
        r.update({k: v for k, v in r.pop("final_info").items() if k != "is_success"})
    return results


def load_policy(task: str, method: str, models_dir: str | Path) -> bc.BCPolicy:
    """A trained twin policy (target end positions of both robots from the Y state)."""
    policy, _ = bc.BCPolicy.load(Path(models_dir) / method, registry.get(task).layout, action_bounds=None)
    return policy


def evaluate_seed(task: str, p: TwinParams, seed: int, models_dir: str | Path,
                  video_root: str | Path | None = None) -> list[dict]:
    """Per-trial results of both methods with one seed's policies (``models_dir``) in the twin's Y, from the fixed
    start states of ``p.start_states`` (the same for every seed); ``p.videos`` videos of each method under
    ``video_root/<task>-<method>`` when it is given."""
    rows = []
    with torch.no_grad():
        for method in TWIN_METHODS:
            policy = load_policy(task, method, models_dir)
            vdir = Path(video_root) / f"{task}-{method}" if video_root else None
            for r in evaluate_policy(task, policy, p.trials, purpose=p.start_states,
                                     videos=p.videos if vdir else 0, video_dir=vdir):
                rows.append({"task": task, "method": method, "seed": seed, "trial": r["trial"],
                             "success": bool(r["success"]), "steps": r["steps"], "start_seed": r["seed"]})
    return rows


def twin_evaluate_job(job: SeedJob, progress=None) -> list[dict]:
    """:func:`evaluate_seed` as a worker's job."""
    p = job.params
    torch.set_num_threads(1)
    rows = evaluate_seed(job.task, p, job.seed, job.models_dir, job.video_dir)
    if progress is not None:
        progress.update(1)
    return rows
