"""DVC stage: dynamics, translator and BC (LfDT and BC without translation) for one real-robot task."""

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
    params = {"twin": {k: v for k, v in p.model_dump().items() if k in ("seed", "dynamics", "translator", "bc")}}
    with tracking.stage_run("twin_train", params, tags={"task": args.task, "seed": p.seed},
                            run_name=f"twin_train-{args.task}") as run:
        res = twin_pipeline.train(args.task, p, Path("models/twin") / args.task,
                                  log=lambda m, i: run.metrics({f"translator/{k}": v for k, v in m.items()}, i))
        flat = {f"{k}/{kk}": vv for k, v in res.items() for kk, vv in v.items()
                if isinstance(vv, int | float) and not isinstance(vv, bool)}
        run.metrics(flat)
        stage.write_json(Path("reports/twin") / f"{args.task}_train.json",
                         {"task": args.task, **res, "stage_wall_s": stage.wall_since_start(),
                          "mlflow_run_id": run.run_id})
    print(f"{args.task}: dynamics F ratio {res['dynamics']['forward_ratio']:.3f}, "
          f"F^-1 ratio {res['dynamics']['inverse_ratio']:.3f}")


if __name__ == "__main__":
    stage.main(run)
