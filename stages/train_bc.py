"""DVC stage: behaviour cloning of one (method, demos, seed) from its training set in data/bc_train/."""

import argparse
from pathlib import Path

from lfdt import bc, data, layout, stage, tracking

BC_METHODS = ("bc_no_translation", "lfdt", "lfdt_no_dyn", "lfdt_no_id")


def run() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    stage.add_config_arguments(ap, BC_METHODS)
    args = ap.parse_args()
    cfg = stage.params(args.params).bc
    name = stage.config_name(args.method, args.demos, args.seed)
    src = Path("data/bc_train") / name
    if args.method == "bc_no_translation":
        tasks = bc.tasks_for(args.method, raw_demos={
            pr: data.read_transitions(src / f"raw_{pr}.parquet") for pr in layout.PAIRINGS})
    else:
        tasks = bc.tasks_for(args.method, translated=data.read_transitions(src / "translated.parquet"))
    tags = {"method": args.method, "demos": args.demos, "seed": args.seed, "config": name}
    with tracking.stage_run("train_bc", {"bc": cfg.model_dump(), "method": args.method, "demos": args.demos,
                                         "seed": args.seed}, tags=tags, run_name=f"train_bc-{name}") as run:
        members, metrics, curves = [], {}, []
        with stage.progress(cfg.iterations * len(tasks), f"BC {name}", "it") as bar:
            for task in tasks:
                member, st = bc.train_member(task, cfg, args.seed, log=lambda m, i: run.metrics(m, i), progress=bar)
                members.append(member)
                for c in st.pop("curve"):
                    curves.append({"member": task.name, **{k.split("/")[-1]: v for k, v in c.items()}})
                metrics.update({f"{task.name}/{k}": v for k, v in st.items()})
        policy = bc.BCPolicy(members)
        out = Path("models/bc") / name
        policy.save(out, {"method": args.method, "demos": args.demos, "seed": args.seed, "bc": cfg.model_dump(),
                          "members": [t.name for t in tasks]})
        metrics.update({"method": args.method, "demos": args.demos, "seed": args.seed,
                        "stage_wall_s": stage.wall_since_start(), "mlflow_run_id": run.run_id})
        stage.write_json(Path("reports/bc") / f"{name}.json", metrics)
        stage.write_csv(Path("reports/bc") / f"{name}_curve.csv", curves)
        run.metrics({k: v for k, v in metrics.items() if isinstance(v, int | float)})


if __name__ == "__main__":
    stage.main(run)
