"""DVC stage: random motion and demonstrations of one real-robot task, from the twin or from robot recordings."""

from pathlib import Path

from lfdt import mlflow_runs, stage, tasks
from lfdt.twin import pipeline as twin_pipeline


def run() -> None:
    task, all_params = stage.task_arguments(__doc__, tasks.NAMES)
    p = all_params.twin
    with mlflow_runs.stage_run("twin_collect", {"twin": p.model_dump()},
                            tags={"task": task, "seeds": ",".join(map(str, p.seeds)), "backend": p.backend},
                            run_name=f"{task} twin_collect") as run:
        stats = twin_pipeline.collect(task, p)
        flat = {f"{s}/{k}/{kk}": vv for s, per in stats.items() for k, v in per.items() for kk, vv in v.items()
                if isinstance(vv, int | float)}
        run.metrics(flat)
        stage.write_report(Path("reports/twin") / f"{task}_data.json",
                           {"task": task, "backend": p.backend, **stats, "stage_wall_s": stage.wall_since_start(),
                            "mlflow_run_id": run.run_id})
    for s, per in stats.items():
        print(f"{task} {s}: " + ", ".join(f"{k} {v['transitions']}" for k, v in per.items()))


if __name__ == "__main__":
    stage.main(run)
