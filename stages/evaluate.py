"""DVC stage: run one (method, demos, seed) BC policy in domain Y from the fixed evaluation start states."""

import argparse
from pathlib import Path

import numpy as np

from lfdt import bc, evaluation, stage, tracking

BC_METHODS = ("bc_no_translation", "lfdt", "lfdt_no_dyn", "lfdt_no_id")


def run() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    stage.add_config_arguments(ap, BC_METHODS)
    args = ap.parse_args()
    p = stage.params(args.params)
    cfg = p.evaluation
    name = stage.config_name(args.method, args.demos, args.seed)
    policy, _ = bc.BCPolicy.load(Path("models/bc") / name)
    tags = {"method": args.method, "demos": args.demos, "seed": args.seed, "config": name, "domain": "Y"}
    with tracking.stage_run("evaluate", {"evaluation": cfg.model_dump(), "method": args.method,
                                         "demos": args.demos, "seed": args.seed}, tags=tags,
                            run_name=f"evaluate-{name}") as run:
        with stage.progress(cfg.trials, f"evaluate {name}", "trial") as bar:
            trials = evaluation.run_trials(policy, p.env, cfg.trials, cfg.videos, Path("reports/videos") / name,
                                           cfg.video_size, progress=bar)
        successes = sum(t["success"] for t in trials)
        summary = {"method": args.method, "demos": args.demos, "seed": args.seed, "successes": successes,
                   "trials": len(trials), "success_rate": successes / len(trials),
                   "mean_final_box_distance_m": float(np.mean([t["final_box_distance_m"] for t in trials])),
                   "mean_final_yaw_error_rad": float(np.mean([t["final_yaw_error_rad"] for t in trials])),
                   "stage_wall_s": stage.wall_since_start(), "mlflow_run_id": run.run_id, "per_trial": trials}
        stage.write_json(Path("reports/eval") / f"{name}.json", summary)
        run.metrics({k: v for k, v in summary.items() if isinstance(v, int | float) and not isinstance(v, bool)})
        run.artifact(Path("reports/videos") / name, "videos")
    print(f"{name}: {successes}/{len(trials)} successes")


if __name__ == "__main__":
    stage.main(run)
