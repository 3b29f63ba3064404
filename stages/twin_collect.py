"""DVC stage: random motion and demonstrations of one real-robot task, from the twin or from robot recordings."""

from pathlib import Path

from lfdt import stage, tracking
from lfdt.robot import twin, twin_pipeline


def run() -> None:
    task, all_params = stage.task_arguments(__doc__, twin.TASKS)
    p = all_params.twin
    with tracking.stage_run("twin_collect", {"twin": p.model_dump()},
                            tags={"task": task, "seed": p.seed, "backend": p.backend},
                            run_name=f"twin_collect-{task}") as run:
        stats = twin_pipeline.collect(task, p)
        flat = {f"{k}/{kk}": vv for k, v in stats.items() for kk, vv in v.items() if isinstance(vv, int | float)}
        run.metrics(flat)
        stage.write_json(Path("reports/twin") / f"{task}_data.json",
                         {"task": task, "backend": p.backend, **stats, "stage_wall_s": stage.wall_since_start(),
                          "mlflow_run_id": run.run_id})
    print(f"{task}: " + ", ".join(f"{k} {v['transitions']}" for k, v in stats.items()))


if __name__ == "__main__":
    stage.main(run)
