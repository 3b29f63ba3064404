"""DVC stage: behaviour cloning of one (method, demos), every seed side by side, from data/bc_train/."""

from pathlib import Path

from lfdt import methods, parallel, stage
from lfdt.jobs import common
from lfdt.jobs.bc import bc_job
from lfdt.nets import torch_device


def run() -> None:
    method, demos, params_path, p = stage.matrix_arguments(__doc__, methods.METHODS)
    torch_device(p.device)  # before any job starts
    cfgs = common.configs(method, demos, p.grid.seeds, params_path)
    members = 2 if methods.get(method).data == "raw" else 1
    results = parallel.run_jobs(bc_job, cfgs, p.grid.workers, total=p.bc.iterations * members * len(cfgs),
                                desc=f"BC {cfgs[0].group}")
    out = Path("reports/bc")
    stage.write_report(out / f"{cfgs[0].group}.json", stage.group_report(results))
    stage.write_csv(out / f"{cfgs[0].group}_curve.csv", [c for r in results for c in r["curve"]])


if __name__ == "__main__":
    stage.main(run)
