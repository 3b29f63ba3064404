"""DVC stage: roll out the SAC expert of one pairing until enough successful demonstrations."""

import argparse
from pathlib import Path

from lfdt import data, experts, layout, mlflow_runs, stage


def run() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--pairing", required=True, choices=layout.PAIRINGS)
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    p = stage.params(args.params)
    cfg = p.demos
    model, expert_cfg = experts.load_expert(Path("models/experts") / args.pairing)
    if expert_cfg["env"] != p.env.model_dump():
        raise SystemExit(f"error: models/experts/{args.pairing} was trained with other env params than "
                         f"params.yaml's env section; rerun train_experts (dvc repro does)")
    if experts.protocol_doc(experts.expert_demos_config(expert_cfg)) != experts.protocol_doc(cfg):
        raise SystemExit(f"error: models/experts/{args.pairing} was trained for another demonstration protocol or "
                         f"robot program than params.yaml's demos.protocol / demos.program; rerun train_experts")
    out = Path("data/demos") / f"{args.pairing}.parquet"
    with mlflow_runs.stage_run("collect_demos", {"env": p.env.model_dump(), "demos": cfg.model_dump()},
                            tags={"pairing": args.pairing, "seed": cfg.seed, "protocol": cfg.protocol},
                            run_name=f"{args.pairing} collect_demos") as run:
        with stage.progress(cfg.per_pairing, f"demos {args.pairing}", "demo") as bar:
            table, stats = experts.collect_demos(model, args.pairing, p.env, cfg, progress=lambda: bar.update(1))
        data.write_table(table, out)
        data.check_transitions(out, "demos", args.pairing, layout.BOX_PUSH)
        stats["stage_wall_s"] = stage.wall_since_start()
        run.metrics(stats)
        stage.write_report(Path("reports/demos") / f"{args.pairing}.json",
                           {"pairing": args.pairing, **stats, "mlflow_run_id": run.run_id})
    print(f"{args.pairing}: {stats['demonstrations']} demonstrations from {stats['attempts']} attempts, "
          f"mean length {stats['mean_demo_length']:.1f} steps")


if __name__ == "__main__":
    stage.main(run)
