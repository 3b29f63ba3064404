"""DVC stage: re-execute the translated demonstrations of one (method, demos) in Y, every seed side by side
(the lfdt_track row; our extension)."""

from pathlib import Path

from lfdt import methods, parallel, stage
from lfdt.jobs import common
from lfdt.jobs.track import track_job


def run() -> None:
    method, demos, params_path, p = stage.matrix_arguments(
        __doc__, [m.name for m in methods.METHODS.values() if m.data == "executed"])
    cfgs = common.configs(method, demos, p.grid.seeds, params_path)
    results = parallel.run_jobs(track_job, cfgs, p.grid.workers, total=2 * demos * len(cfgs),
                                desc=f"re-execute {cfgs[0].group}", unit="demo")
    stage.write_report(Path("reports/track") / f"{cfgs[0].group}.json", stage.group_report(results))
    for r in results:
        m = r["metrics"]
        print(f"{cfgs[0].group} seed {m['seed']}: {m['successful_executions']}/{m['executions']} executions succeed")


if __name__ == "__main__":
    stage.main(run)
