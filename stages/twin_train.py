"""DVC stage: dynamics, translator and BC (LfDT and BC without translation) for one real-robot task, its seeds side
by side."""

import lfdt.numerics  # noqa: F401  (first: pins the numeric code paths before numpy, torch or mujoco load)

from lfdt import parallel, stage
from lfdt.tasks import registry
from lfdt.twin.common import SeedJob

TWIN_TRAIN_JOB = parallel.Job("lfdt.twin.train", "twin_train_job")
"""By name: this process never imports torch; each job checks params.yaml's device before it opens its run."""


def run() -> None:
    args, all_params = stage.task_arguments(__doc__, registry.PLANAR, {
        "data-dir": "the recordings, a folder per task", "models": "where the models go, a folder per task",
        "reports": "where the report <task>_train.json goes"})
    task, p = args.task, all_params.twin
    registry.check_twin_names(p)
    jobs = [SeedJob(task, seed, p, all_params.device, data_root=str(args.data_dir),
                                  models_dir=str(args.models / task / f"s{seed}")) for seed in p.seeds]
    tcfg = p.translator_for(task)
    # one MLflow run per seed, as the matrix stages' jobs: the stage's frame opens none
    with stage.frame(args.reports / f"{task}_train.json") as f:
        results = parallel.run_jobs(TWIN_TRAIN_JOB, jobs, all_params.grid.workers,
                                    total=tcfg.steps * len(jobs), desc=f"twin_train {task}")
        per_seed = {str(j.seed): r for j, r in zip(jobs, results, strict=True)}
        f.report.update({"task": task, "seeds": per_seed})
    for seed, res in per_seed.items():
        print(f"{task} seed {seed}: dynamics F ratio {res['dynamics']['forward_ratio']:.3f}, "
              f"F^-1 ratio {res['dynamics']['inverse_ratio']:.3f}")


if __name__ == "__main__":
    stage.main(run)
