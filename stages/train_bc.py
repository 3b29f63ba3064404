"""DVC stage: behaviour cloning of one (method, demos) for every seed, from the BC training sets. The seeds train as
stacked models, split into ``grid.workers`` groups that run side by side."""

import lfdt.numerics  # noqa: F401  (first: pins the numeric code paths before numpy, torch or mujoco load)

from lfdt import methods, parallel, stage
from lfdt.box_push_jobs import common
from lfdt.rendering import check_videos

BC_JOB = parallel.Job("lfdt.box_push_jobs.bc", "bc_job")
"""By name: this process never imports torch; each job checks params.yaml's device before it loads anything."""


def run() -> None:
    args, p = stage.matrix_arguments(__doc__, methods.METHODS, {
        "bc-data": "the BC training sets, a folder per configuration",
        "dynamics-dir": "F and F^-1 (bc.recovery_copies relabels with F^-1)",
        "policies": "where the policies go, a folder per configuration",
        "reports": "where the report <method>-d<demos>.json and its learning curve go"})
    check_videos(p.evaluation.videos, "evaluation.videos")  # evaluate.py renders them next, in the same DVC stage
    cfgs = common.configs(args.method, args.demos, p.grid.seeds, p, bc_data_dir=args.bc_data,
                          policies_dir=args.policies, dynamics_dir=args.dynamics_dir)
    group = cfgs[0].group
    members = 2 if methods.get(args.method).data == "raw" else 1
    with stage.frame(args.reports / f"{group}.json") as f:
        results = common.flatten(parallel.run_jobs(
            BC_JOB, common.groups(cfgs, p.grid.workers), p.grid.workers, total=p.bc.iterations * members * len(cfgs),
            desc=f"BC {group}", unit="seed-it"))
        f.report.update(stage.group_report(results))
        stage.write_csv(args.reports / f"{group}_curve.csv", [c for r in results for c in r["curve"]])


if __name__ == "__main__":
    stage.main(run)
