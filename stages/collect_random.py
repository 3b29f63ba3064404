"""DVC stage: collect random-motion transitions in one domain (batched MuJoCo rollouts) to Parquet."""

import argparse
from pathlib import Path

from lfdt import data, layout, mlflow_runs, random_motion, stage


def run() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--domain", required=True, choices=layout.DOMAINS)
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    p = stage.params(args.params)
    cfg = p.random
    out = Path("data/random") / f"{args.domain}.parquet"
    with mlflow_runs.stage_run("collect_random", {"env": p.env.model_dump(), "random": cfg.model_dump()},
                            tags={"domain": args.domain, "seed": cfg.seed},
                            run_name=f"{args.domain} collect_random") as run:
        with stage.progress(cfg.transitions, f"random {args.domain}", "tr") as bar:
            table, stats = random_motion.collect_random(args.domain, p.env, cfg, progress=bar.update)
        data.write_table(table, out)
        data.check_transitions(out, "random", args.domain, layout.BOX_PUSH)
        stats["file_mb"] = out.stat().st_size / 1e6
        stats["stage_wall_s"] = stage.wall_since_start()
        run.metrics(stats)
        stage.write_report(Path("reports/random") / f"{args.domain}.json",
                           {"domain": args.domain, **stats, "mlflow_run_id": run.run_id})
    print(f"{args.domain}: {stats['transitions']} transitions in {stats['wall_s']:.1f} s "
          f"({stats['transitions_per_s']:.0f}/s)")


if __name__ == "__main__":
    stage.main(run)
