"""DVC stage: train the translator (G, D; eqs. 1-6) of one (method, demos) for every seed, side by side, and
translate the demonstrations."""

from pathlib import Path

from lfdt import methods, parallel, stage, translation
from lfdt.jobs import common
from lfdt.jobs.translator import translator_job
from lfdt.nets import torch_device


def run() -> None:
    method, demos, params_path, p = stage.matrix_arguments(__doc__, methods.translator_methods())
    torch_device(p.device)  # before any job starts
    cfgs = common.configs(method, demos, p.grid.seeds, params_path)
    tcfg = translation.method_config(method, p.translator)
    results = parallel.run_jobs(translator_job, cfgs, p.grid.workers, total=tcfg.iterations * tcfg.restarts * len(cfgs),
                                desc=f"translator {cfgs[0].group}")
    out = Path("reports/translator")
    stage.write_report(out / f"{cfgs[0].group}.json", stage.group_report(results))
    # held-out losses are measured every select_every iterations, diagnostics every log_every
    stage.write_csv(out / f"{cfgs[0].group}_curve.csv", [c for r in results for c in r["curve"]])
    for r in results:
        m = r["metrics"]
        print(f"{cfgs[0].group} seed {m['seed']}: held-out loss {m['selected_heldout_loss']:.3f} at iteration "
              f"{m['selected_iteration']}, replay success {m['replay_success_rate']:.2f}")


if __name__ == "__main__":
    stage.main(run)
