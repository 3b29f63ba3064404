"""DVC stage: random motion and demonstrations of one real-robot task, from the twin or from robot recordings."""

import lfdt.numerics  # noqa: F401  (first: pins the numeric code paths before numpy, torch or mujoco load)

import shutil

from lfdt import parallel, stage
from lfdt.tasks import registry
from lfdt.twin.common import SeedJob

COLLECT_JOB = parallel.Job("lfdt.twin.collect", "twin_collect_job")
"""By name: this process never imports torch or MuJoCo (its workers do, once)."""


def run() -> None:
    args, all_params = stage.task_arguments(__doc__, registry.PLANAR, {
        "data-dir": "where the recordings go, a folder per task", "reports": "where the report <task>_data.json goes"})
    task, p = args.task, all_params.twin
    with stage.frame(args.reports / f"{task}_data.json", "twin_collect", {"twin": p.model_dump()},
                     tags={"task": task, "seeds": ",".join(map(str, p.seeds)), "backend": p.backend},
                     run_name=f"{task} twin_collect") as f:
        shutil.rmtree(args.data_dir / task, ignore_errors=True)
        jobs = [SeedJob(task, seed, p, all_params.device, data_root=str(args.data_dir)) for seed in p.seeds]
        per_seed = parallel.run_jobs(COLLECT_JOB, jobs, all_params.grid.workers, total=len(jobs),
                                     desc=f"twin_collect {task}", unit="seed",
                                     preload=())  # its jobs log nothing to MLflow: this process's frame does
        stats = {f"s{j.seed}": s for j, s in zip(jobs, per_seed, strict=True)}
        f.metrics({f"{s}/{k}/{kk}": vv for s, per in stats.items() for k, v in per.items() for kk, vv in v.items()})
        f.report.update({"task": task, "backend": p.backend, **stats})
    for s, per in stats.items():
        print(f"{task} {s}: " + ", ".join(f"{k} {v['transitions']}" for k, v in per.items()))


if __name__ == "__main__":
    stage.main(run)
