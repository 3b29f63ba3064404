"""DVC stage: Table I (md, csv, tex, and its headline rates as the metrics file), per-run CSV, plots that overlay the
methods, translator diagnostics, stage wall times, and one MLflow parent run that carries them."""

import argparse
import json

from lfdt import mlflow_runs, mlflow_views, report, stage

# bookkeeping files (runs/) of the runs behind Table I: one run each, or one per seed
RUN_FILES = ("experts/*_train.json", "random/*.json", "demos/*.json", "dynamics.json",
             "translator/*.json", "track/*.json", "bc/*.json", "eval/*.json")


def run() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    p = stage.params(args.params)
    reports, runs = stage.REPORTS, stage.RUNS
    trials = report.load_trials(reports / "eval")
    expected = {(m, d, s) for m in p.grid.bc_methods for d in p.grid.demos for s in p.grid.seeds}
    keep = [(m, d, s) in expected for m, d, s in zip(trials.method, trials.demos, trials.seed)]
    trials = trials[keep]
    missing = expected - set(zip(trials.method, trials.demos, trials.seed))
    if missing:
        raise SystemExit(f"error: no evaluation for {sorted(missing)} in reports/eval; run `dvc repro`")
    run_rows = report.runs(trials)
    table = report.aggregate(trials)
    stage.write_csv(reports / "table1_runs.csv", run_rows.to_dict("records"))
    stage.write_csv(reports / "table1.csv", table.to_dict("records"))
    (reports / "table1.md").write_text(report.markdown(table))
    (reports / "table1.tex").write_text(report.latex(table))
    stage.write_csv(reports / "success_vs_demos.csv", run_rows[["method", "demos", "seed", "success_rate"]]
                    .to_dict("records"))
    png = report.plot(run_rows, table, reports / "success_vs_demos.png")
    curves_png = report.plot_translator_curves(reports / "translator", reports / "translator_curves.png")
    diag = report.translator_diagnostics(reports / "translator", reports / "track")
    stage.write_csv(reports / "translator_diagnostics.csv", diag.to_dict("records"))
    # the top-level plots of dvc.yaml: one chart per quantity, the methods overlaid
    plots = reports / "plots"
    plots.mkdir(exist_ok=True)
    stage.write_csv(plots / "success_by_method.csv", report.success_by_method(table).to_dict("records"))
    stage.write_csv(plots / "bc_val_loss_by_method.csv",
                    report.curves_by_method(reports / "bc", "val_loss").to_dict("records"))
    for name, column in (("translator_heldout_loss", "heldout/selection_loss"), ("translator_dyn_loss", "loss/dyn"),
                         ("translator_D_accuracy", "D/accuracy")):
        stage.write_csv(plots / f"{name}_by_method.csv",
                        report.curves_by_method(reports / "translator", column).to_dict("records"))
    times = report.stage_times(runs)
    stage.write_csv(reports / "stage_times.csv", times.to_dict("records"))
    headline = report.headline(table)
    # one parent run per pipeline run: it carries the table and plot, and adopts the runs behind them
    children = [i for pattern in RUN_FILES for f in sorted(runs.glob(pattern))
                for i in stage.run_ids(json.loads(f.read_text()))]
    total_wall = float(times.total_s.sum())
    with mlflow_runs.stage_run("report", {"grid": p.grid.model_dump()}, tags={"pipeline_parent": "true"},
                               run_name=mlflow_runs.pipeline_run_name("pipeline")) as parent:
        parent.metrics({f"{m}_d{d.removeprefix('d')}_success_rate": v
                        for m, row in headline.items() for d, v in row.items()})
        parent.metrics({"total_stage_wall_s": total_wall})
        for f in ("table1.md", "table1.csv", "table1.tex", "table1_runs.csv", "translator_diagnostics.csv",
                  "stage_times.csv"):
            parent.artifact(reports / f)
        parent.artifact(png)
        parent.artifact(curves_png)
        adopted = mlflow_runs.adopt_children(parent.run_id, children)
        # a reused run moves on to the newest parent run (MLflow keeps one parent per run); this list stays
        parent.dict({"runs": list(dict.fromkeys(children))}, "children.json")
        parent_id = parent.run_id
    mlflow_views.install()  # the UI's views of these runs (README: MLflow), after the parent run they show
    stage.write_report(reports / "table1.json", {**headline, "mlflow_parent_run_id": parent_id,
                                                 "mlflow_child_runs": adopted, "total_stage_wall_s": total_wall})
    print(report.markdown(table))
    print(times.to_string(index=False))


if __name__ == "__main__":
    stage.main(run)
