"""DVC stage: dynamics, translator and BC (LfDT and BC without translation) for one real-robot task."""

from lfdt import mlflow_runs, stage
from lfdt.errors import StageError
from lfdt.nets import torch_device
from lfdt.tasks import registry
from lfdt.twin import pipeline as twin_pipeline


def run() -> None:
    args, all_params = stage.task_arguments(__doc__, registry.PLANAR, {
        "data-dir": "the recordings, a folder per task", "models": "where the models go, a folder per task",
        "reports": "where the report <task>_train.json goes"})
    task, p, device = args.task, all_params.twin, torch_device(all_params.device)
    unknown = sorted(set(p.task_translator) - set(registry.PLANAR))
    if unknown:
        raise StageError(f"params.yaml twin.task_translator: unknown task(s) {unknown}; the tasks are "
                               f"{list(registry.PLANAR)}")
    params = {"twin": {"seeds": p.seeds, "dynamics": p.dynamics.model_dump(),
                       "translator": p.translator_for(task).model_dump(), "bc": p.bc.model_dump()},
              "device": all_params.device}
    # one MLflow run per seed, as the matrix stages' jobs: the stage's frame opens none
    with stage.frame(args.reports / f"{task}_train.json") as f:
        per_seed = {}
        for seed in p.seeds:
            with mlflow_runs.stage_run("twin_train", params, tags={"task": task, "seed": seed},
                                       run_name=f"{task}-s{seed} twin_train") as run:
                def log(m: dict, i: int, r=run) -> None:
                    r.metrics({f"translator/{k}": v for k, v in m.items()}, i)

                res = twin_pipeline.train(task, p, seed, args.models / task / f"s{seed}", args.data_dir,
                                          device=device, log=log)
                run.metrics(stage.numeric({f"{k}/{kk}": vv for k, v in res.items() for kk, vv in v.items()}))
                per_seed[str(seed)] = {**res, "mlflow_run_id": run.run_id}
            print(f"{task} seed {seed}: dynamics F ratio {res['dynamics']['forward_ratio']:.3f}, "
                  f"F^-1 ratio {res['dynamics']['inverse_ratio']:.3f}")
        f.report.update({"task": task, "seeds": per_seed})


if __name__ == "__main__":
    stage.main(run)
