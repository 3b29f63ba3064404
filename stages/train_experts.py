"""DVC stage: train the SAC expert of one pairing (resumable), evaluate it on fresh seeds."""

import argparse
from pathlib import Path

from lfdt import experts, layout, stage, tracking


def run() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--pairing", required=True, choices=layout.PAIRINGS)
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    p = stage.params(args.params)
    cfg, env_cfg = p.experts, p.env
    out = Path("models/experts") / args.pairing
    reports = Path("reports/experts")
    demos_cfg = p.demos
    with tracking.stage_run("train_experts", {"env": env_cfg.model_dump(), "experts": cfg.model_dump(),
                                              **experts.protocol_doc(demos_cfg)},
                            tags={"pairing": args.pairing, "seed": cfg.seed, "protocol": demos_cfg.protocol},
                            run_name=f"train_experts-{args.pairing}") as run:
        with stage.progress(cfg.total_timesteps, f"SAC {args.pairing}", "step") as bar:
            model, stats = experts.train_expert(
                args.pairing, env_cfg, cfg, demos_cfg, Path("checkpoints/experts") / args.pairing,
                log=lambda m, step: run.metrics(m, step), progress=bar)
        ev = experts.evaluate_expert(model, args.pairing, env_cfg, demos_cfg, cfg.eval_episodes, cfg.seed)
        curve = stats.pop("curve")
        summary = {"pairing": args.pairing, "protocol": demos_cfg.protocol, **ev, **stats, "stage_wall_s": stage.wall_since_start(),
                   "mlflow_run_id": run.run_id}
        experts.save_expert(model, out, args.pairing, env_cfg, cfg, demos_cfg, {"evaluation": ev, "training": stats})
        stage.write_json(reports / f"{args.pairing}_train.json", summary)
        stage.write_csv(reports / f"{args.pairing}_curve.csv",
                        [{"timesteps": c["timesteps"], "success_rate": c["train/success_rate_last100"],
                          "episode_return": c["train/episode_return_last100"]} for c in curve])
        run.metrics({f"eval/{k}": v for k, v in ev.items() if isinstance(v, int | float)})
        run.metrics({k: v for k, v in stats.items() if isinstance(v, int | float)})
        run.artifact(out / "config.json")
        run.artifact(reports / f"{args.pairing}_curve.csv")
        experts.Checkpoints(Path("checkpoints/experts") / args.pairing, "").clear()
    print(f"{args.pairing}: success rate {ev['success_rate']:.2f} over {ev['episodes']} episodes, "
          f"{stats['wall_time_s'] / 60:.1f} min, {stats['env_steps_per_s']:.0f} env steps/s")


if __name__ == "__main__":
    stage.main(run)
