"""DVC stage: dynamics, translator and BC (LfDT and BC without translation) for one real-robot task."""

from pathlib import Path

from lfdt import mlflow_runs, stage, tasks
from lfdt.nets import torch_device
from lfdt.twin import pipeline as twin_pipeline


def run() -> None:
    task, all_params = stage.task_arguments(__doc__, tasks.NAMES)
    p, device = all_params.twin, torch_device(all_params.device)
    params = {"twin": {k: v for k, v in p.model_dump().items() if k in ("seeds", "dynamics", "translator", "bc")},
              "device": all_params.device}
    per_seed = {}
    for seed in p.seeds:
        with mlflow_runs.stage_run("twin_train", params, tags={"task": task, "seed": seed},
                                   run_name=f"{task}-s{seed} twin_train") as run:
            def log(m: dict, i: int, r=run) -> None:
                r.metrics({f"translator/{k}": v for k, v in m.items()}, i)

            res = twin_pipeline.train(task, p, seed, Path("models/twin") / task / f"s{seed}", device=device, log=log)
            run.metrics({f"{k}/{kk}": vv for k, v in res.items() for kk, vv in v.items()
                         if isinstance(vv, int | float) and not isinstance(vv, bool)})
            per_seed[str(seed)] = {**res, "mlflow_run_id": run.run_id}
        print(f"{task} seed {seed}: dynamics F ratio {res['dynamics']['forward_ratio']:.3f}, "
              f"F^-1 ratio {res['dynamics']['inverse_ratio']:.3f}")
    stage.write_report(Path("reports/twin") / f"{task}_train.json",
                       {"task": task, "seeds": per_seed, "stage_wall_s": stage.wall_since_start()})


if __name__ == "__main__":
    stage.main(run)
