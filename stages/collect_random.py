"""DVC stage: collect random-motion transitions in one domain (batched MuJoCo rollouts) to Parquet."""

import lfdt.numerics  # noqa: F401  (first: pins the numeric code paths before numpy, torch or mujoco load)

from lfdt import data, layout, stage
from lfdt.tasks.box_push import columns as box_columns
from lfdt.tasks.box_push import random_motion


def run() -> None:
    ap = stage.parser(__doc__, {"out-dir": "where <domain>.parquet goes",
                                "reports": "where the report <domain>.json goes"})
    ap.add_argument("--domain", required=True, choices=layout.DOMAINS)
    args = ap.parse_args()
    p = stage.params(args.params)
    cfg = p.random
    out = args.out_dir / f"{args.domain}.parquet"
    with stage.frame(args.reports / f"{args.domain}.json", "collect_random",
                     {"env": p.env.model_dump(), "random": cfg.model_dump()},
                     tags={"domain": args.domain, "seed": cfg.seed}, run_name=f"{args.domain} collect_random") as f:
        with f.progress(cfg.transitions, f"random {args.domain}", "tr") as bar:
            table, stats = random_motion.collect_random(args.domain, p.env, cfg, progress=bar.update)
        data.write_table(table, out)
        data.check_transitions(out, "random", args.domain, box_columns.BOX_PUSH)
        stats["file_mb"] = out.stat().st_size / 1e6
        f.metrics(stats)
        f.report.update({"domain": args.domain, **stats})
    print(f"{args.domain}: {stats['transitions']} transitions in {stats['wall_s']:.1f} s "
          f"({stats['transitions_per_s']:.0f}/s)")


if __name__ == "__main__":
    stage.main(run)
