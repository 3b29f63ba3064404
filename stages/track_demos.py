"""DVC stage: re-execute the translated demonstrations of one (method, demos) in Y, every seed side by side
(the lfdt_track row; our extension)."""

import lfdt.numerics  # noqa: F401  (first: pins the numeric code paths before numpy, torch or mujoco load)

from lfdt import methods, parallel, stage
from lfdt.box_push_jobs import common

TRACK_JOB = parallel.Job("lfdt.box_push_jobs.track", "track_job")
"""By name: this process never imports torch or MuJoCo (its workers do, once)."""


def run() -> None:
    args, p = stage.matrix_arguments(__doc__, [m.name for m in methods.METHODS.values() if m.data == "executed"], {
        "bc-data": "the translated demonstrations, and where the executed ones go, a folder per configuration",
        "dynamics-dir": "F and F^-1", "reports": "where the report <method>-d<demos>.json goes"})
    cfgs = common.configs(args.method, args.demos, p.grid.seeds, p, bc_data_dir=args.bc_data,
                          dynamics_dir=args.dynamics_dir)
    group = cfgs[0].group
    with stage.frame(args.reports / f"{group}.json") as f:
        results = parallel.run_jobs(TRACK_JOB, cfgs, p.grid.workers, total=2 * args.demos * len(cfgs),
                                    desc=f"re-execute {group}", unit="demo")
        f.report.update(stage.group_report(results))
    for r in results:
        m = r["metrics"]
        print(f"{group} seed {m['seed']}: {m['successful_executions']}/{m['executions']} executions succeed")


if __name__ == "__main__":
    stage.main(run)
