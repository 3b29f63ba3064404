"""DVC stage: run the BC policies of one (method, demos), every seed side by side, in domain Y from the fixed
evaluation start states."""

from pathlib import Path

from lfdt import methods, parallel, stage
from lfdt.jobs import common
from lfdt.jobs.evaluate import evaluate_job


def run() -> None:
    method, demos, params_path, p = stage.matrix_arguments(__doc__, methods.METHODS)
    cfgs = common.configs(method, demos, p.grid.seeds, params_path)
    (common.VIDEOS / cfgs[0].group).mkdir(parents=True, exist_ok=True)  # a DVC output, also with no videos
    results = parallel.run_jobs(evaluate_job, cfgs, p.grid.workers, total=p.evaluation.trials * len(cfgs),
                                desc=f"evaluate {cfgs[0].group}", unit="trial")
    out = Path("reports/eval")
    stage.write_report(out / f"{cfgs[0].group}.json", stage.group_report(results))
    stage.write_csv(out / f"{cfgs[0].group}_trials.csv", [t for r in results for t in r["trials"]])
    for r in results:
        m = r["metrics"]
        print(f"{cfgs[0].group} seed {m['seed']}: {m['successes']}/{m['trials']} successes")


if __name__ == "__main__":
    stage.main(run)
