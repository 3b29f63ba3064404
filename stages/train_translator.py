"""DVC stage: train the translators (G, D; eqs. 1-6) of one (method, demos) for every seed, and translate the
demonstrations. The seeds train as stacked models, split into ``grid.workers`` groups that run side by side."""

import lfdt.numerics  # noqa: F401  (first: pins the numeric code paths before numpy, torch or mujoco load)

from lfdt import methods, parallel, stage
from lfdt.box_push_jobs import common

TRANSLATOR_JOB = parallel.Job("lfdt.box_push_jobs.translator", "translator_job")
"""By name: this process never imports torch; each job checks params.yaml's device before it loads anything."""


def run() -> None:
    args, p = stage.matrix_arguments(__doc__, methods.translator_methods(), {
        "demos-dir": "the demonstrations, <pairing>.parquet", "random-dir": "the random motion, <domain>.parquet",
        "dynamics-dir": "F and F^-1", "translators": "where the translators go, a folder per configuration",
        "bc-data": "where the translated demonstrations go, a folder per configuration",
        "reports": "where the report <method>-d<demos>.json and its learning curve go",
        "checkpoints": "resumable training state (a killed stage goes on from it), a folder per configuration"})
    cfgs = common.configs(args.method, args.demos, p.grid.seeds, p, demos_dir=args.demos_dir,
                          random_dir=args.random_dir, dynamics_dir=args.dynamics_dir,
                          translators_dir=args.translators, bc_data_dir=args.bc_data,
                          checkpoints_dir=args.checkpoints)
    group = cfgs[0].group
    tcfg = methods.translator_config(args.method, p.translator)
    with stage.frame(args.reports / f"{group}.json") as f:
        results = common.flatten(parallel.run_jobs(
            TRANSLATOR_JOB, common.groups(cfgs, p.grid.workers), p.grid.workers,
            total=tcfg.steps * len(cfgs), desc=f"translator {group}", unit="seed-it"))
        f.report.update(stage.group_report(results))
        # held-out losses are measured every select_every iterations, diagnostics every log_every
        stage.write_csv(args.reports / f"{group}_curve.csv", [c for r in results for c in r["curve"]])
    for r in results:
        m = r["metrics"]
        print(f"{group} seed {m['seed']}: held-out loss {m['selected_heldout_loss']:.3f} at iteration "
              f"{m['selected_iteration']}, replay success {m['replay_success_rate']:.2f}")


if __name__ == "__main__":
    stage.main(run)
