"""DVC stage: run the BC policies of one (method, demos), every seed, in domain Y from the fixed evaluation start
states: the seeds split into ``grid.workers`` groups side by side, each group's trials stepped in lockstep."""

import lfdt.numerics  # noqa: F401  (first: pins the numeric code paths before numpy, torch or mujoco load)

from lfdt import methods, parallel, stage
from lfdt.box_push_jobs import common
from lfdt.box_push_jobs.evaluate import check_policies, evaluate_job
from lfdt.rendering import check_videos


def run() -> None:
    args, p = stage.matrix_arguments(__doc__, methods.METHODS, {
        "policies": "the BC policies, a folder per configuration",
        "videos": "where the videos go, a folder per (method, demos)",
        "reports": "where the report <method>-d<demos>.json and its trials go"})
    check_videos(p.evaluation.videos, "evaluation.videos")
    cfgs = common.configs(args.method, args.demos, p.grid.seeds, p, policies_dir=args.policies,
                          videos_dir=args.videos)
    group = cfgs[0].group
    check_policies(cfgs)
    (args.videos / group).mkdir(parents=True, exist_ok=True)  # a DVC output, also with no videos
    with stage.frame(args.reports / f"{group}.json") as f:
        results = common.flatten(parallel.run_jobs(
            evaluate_job, common.groups(cfgs, p.grid.workers), p.grid.workers,
            total=p.evaluation.trials * len(cfgs), desc=f"evaluate {group}", unit="trial"))
        f.report.update(stage.group_report(results))
        stage.write_csv(args.reports / f"{group}_trials.csv", [t for r in results for t in r["trials"]])
    for r in results:
        m = r["metrics"]
        print(f"{group} seed {m['seed']}: {m['successes']}/{m['trials']} successes")


if __name__ == "__main__":
    stage.main(run)
