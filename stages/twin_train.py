"""DVC stage: dynamics, translator and BC (LfDT and BC without translation) for one real-robot task."""

from pathlib import Path

from lfdt import stage, tracking
from lfdt.robot import twin, twin_pipeline


def run() -> None:
    task, all_params = stage.task_arguments(__doc__, twin.TASKS)
    p = all_params.twin
    params = {"twin": {k: v for k, v in p.model_dump().items() if k in ("seed", "dynamics", "translator", "bc")}}
    with tracking.stage_run("twin_train", params, tags={"task": task, "seed": p.seed},
                            run_name=f"twin_train-{task}") as run:
        res = twin_pipeline.train(task, p, Path("models/twin") / task,
                                  log=lambda m, i: run.metrics({f"translator/{k}": v for k, v in m.items()}, i))
        flat = {f"{k}/{kk}": vv for k, v in res.items() for kk, vv in v.items()
                if isinstance(vv, int | float) and not isinstance(vv, bool)}
        run.metrics(flat)
        stage.write_json(Path("reports/twin") / f"{task}_train.json",
                         {"task": task, **res, "stage_wall_s": stage.wall_since_start(),
                          "mlflow_run_id": run.run_id})
    print(f"{task}: dynamics F ratio {res['dynamics']['forward_ratio']:.3f}, "
          f"F^-1 ratio {res['dynamics']['inverse_ratio']:.3f}")


if __name__ == "__main__":
    stage.main(run)
