"""DVC stage: random motion and demonstrations of one real-robot task, from the twin or from robot recordings."""

import argparse
from pathlib import Path

from lfdt import stage, tracking
from lfdt.robot import twin, twin_pipeline


def run() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--task", required=True, choices=twin.TASKS)
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    p = stage.params(args.params).twin
    with tracking.stage_run("twin_collect", {"twin": p.model_dump()},
                            tags={"task": args.task, "seed": p.seed, "backend": p.backend},
                            run_name=f"twin_collect-{args.task}") as run:
        stats = twin_pipeline.collect(args.task, p)
        flat = {f"{k}/{kk}": vv for k, v in stats.items() for kk, vv in v.items() if isinstance(vv, int | float)}
        run.metrics(flat)
        stage.write_json(Path("reports/twin") / f"{args.task}_data.json",
                         {"task": args.task, "backend": p.backend, **stats, "stage_wall_s": stage.wall_since_start(),
                          "mlflow_run_id": run.run_id})
    print(f"{args.task}: " + ", ".join(f"{k} {v['transitions']}" for k, v in stats.items()))


if __name__ == "__main__":
    stage.main(run)
