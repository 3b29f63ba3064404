"""DVC stage: trials of LfDT and BC without translation on one real-robot task (twin, or the robots' deploy logs)."""

import lfdt.numerics  # noqa: F401  (first: pins the numeric code paths before numpy, torch or mujoco load)

from pathlib import Path

from lfdt import parallel, stage, twin
from lfdt.errors import InputError
from lfdt.rendering import check_videos
from lfdt.rig import deploy_log
from lfdt.tasks import registry
from lfdt.twin.common import SeedJob

EVALUATE_JOB = parallel.Job("lfdt.twin.evaluate", "twin_evaluate_job")
"""By name: this process never imports torch or MuJoCo (its workers do, once)."""


def real_trials(task: str, real_dir: str, seed: int = 0) -> list[dict]:
    """Trial outcomes logged by `python -m lfdt.robot deploy` on the robots (of the policies of ``seed``). A log that
    is missing, empty or not a deploy log (a folder, bytes that are not UTF-8, a bad row) is an InputError naming it
    (:class:`~lfdt.rig.deploy_log.DeployLogError` is one), which ends the stage with one line and exit 2."""
    rows = []
    for method in twin.TWIN_METHODS:
        path = Path(real_dir) / task / f"deploy_{method}.csv"
        trials = deploy_log.read_trials(path)
        if not trials:
            raise InputError(f"backend 'real': no deployment log {path} (or it holds no trial); run "
                             f"`python -m lfdt.robot deploy --task {task} --method {method} ...` on the robots")
        rows += [{"task": task, "method": method, "seed": seed, "trial": t, "success": ok} for t, ok in trials]
    return rows


def run() -> None:
    args, all_params = stage.task_arguments(__doc__, registry.PLANAR, {
        "models": "the models, a folder per task", "videos": "where the videos go, a folder per task",
        "reports": "where the report <task>_eval.json goes"})
    task, p = args.task, all_params.twin
    if p.backend == "sim":
        check_videos(p.videos, "twin.videos")
    video_root = args.videos / task
    video_root.mkdir(parents=True, exist_ok=True)  # a DVC output, also with no videos or the real robots' logs
    with stage.frame(args.reports / f"{task}_eval.json", "twin_evaluate",
                     {"twin": {"trials": p.trials, "backend": p.backend, "seeds": p.seeds,
                               "start_states": p.start_states}},
                     tags={"task": task, "backend": p.backend, "start_states": p.start_states},
                     run_name=f"{task} twin_evaluate") as f:
        if p.backend == "real":
            rows = real_trials(task, p.real_dir, p.seeds[0])
        else:
            jobs = [SeedJob(task, seed, p, all_params.device, models_dir=str(args.models / task / f"s{seed}"),
                                          video_dir=str(video_root) if seed == p.seeds[0] else None)
                    for seed in p.seeds]
            rows = [r for per in parallel.run_jobs(EVALUATE_JOB, jobs, all_params.grid.workers, total=len(jobs),
                                                   desc=f"twin_evaluate {task}", unit="seed",
                                                   preload=())  # its jobs log nothing: this process's frame does
                    for r in per]
        summary = {m: sum(r["success"] for r in rows if r["method"] == m) for m in twin.TWIN_METHODS}
        counts = {m: sum(r["method"] == m for r in rows) for m in twin.TWIN_METHODS}
        f.metrics({f"{m}/successes": v for m, v in summary.items()})
        f.metrics({f"{m}/success_rate": summary[m] / max(counts[m], 1) for m in summary})
        f.report.update({"task": task, "backend": p.backend, "start_states": p.start_states, "trials": counts,
                         "successes": summary,
                         "per_trial": rows})
    print(f"{task}: " + ", ".join(f"{m} {v}/{counts[m]}" for m, v in summary.items()))

if __name__ == "__main__":
    stage.main(run)
