"""DVC stage: roll out the SAC expert of one pairing until enough successful demonstrations."""

import lfdt.numerics  # noqa: F401  (first: pins the numeric code paths before numpy, torch or mujoco load)

from lfdt import data, layout, stage
from lfdt.tasks.box_push import columns as box_columns
from lfdt.tasks.box_push import experts


def run() -> None:
    ap = stage.parser(__doc__, {"experts": "the experts, one folder per pairing",
                                "out-dir": "where <pairing>.parquet goes",
                                "reports": "where the report <pairing>.json goes"})
    ap.add_argument("--pairing", required=True, choices=layout.PAIRINGS)
    args = ap.parse_args()
    p = stage.params(args.params)
    cfg = p.demos
    expert_dir = args.experts / args.pairing
    model, expert_cfg = experts.load_expert(expert_dir)
    if expert_cfg["env"] != p.env.model_dump():
        raise SystemExit(f"error: {expert_dir} was trained with other env params than "
                         f"params.yaml's env section; rerun train_experts (dvc repro does)")
    if experts.protocol_doc(experts.expert_demos_config(expert_cfg)) != experts.protocol_doc(cfg):
        raise SystemExit(f"error: {expert_dir} was trained for another demonstration protocol or "
                         f"robot program than params.yaml's demos.protocol / demos.program; rerun train_experts")
    out = args.out_dir / f"{args.pairing}.parquet"
    with stage.frame(args.reports / f"{args.pairing}.json", "collect_demos",
                     {"env": p.env.model_dump(), "demos": cfg.model_dump()},
                     tags={"pairing": args.pairing, "seed": cfg.seed, "protocol": cfg.protocol},
                     run_name=f"{args.pairing} collect_demos") as f:
        with f.progress(cfg.per_pairing, f"demos {args.pairing}", "demo") as bar:
            table, stats = experts.collect_demos(model, args.pairing, p.env, cfg, progress=lambda: bar.update(1))
        data.write_table(table, out)
        data.check_transitions(out, "demos", args.pairing, box_columns.BOX_PUSH)
        f.metrics(stats)
        f.report.update({"pairing": args.pairing, **stats})
    print(f"{args.pairing}: {stats['demonstrations']} demonstrations from {stats['attempts']} attempts, "
          f"mean length {stats['mean_demo_length']:.1f} steps")


if __name__ == "__main__":
    stage.main(run)
