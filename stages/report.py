"""DVC stage: Table I (md, csv, tex, and its headline rates as the metrics file), per-run CSV, plots that overlay the
methods, translator diagnostics, stage wall times, and one MLflow parent run that carries them."""

import lfdt.numerics  # noqa: F401  (first: pins the numeric code paths before numpy, torch or mujoco load)

import json
from pathlib import Path

from lfdt import mlflow_runs, mlflow_views, report, stage

INPUTS = {"expert-reports": "the experts' reports, <pairing>_train.json",
          "experts-summary": "the experts' summary with the protocol's premise (reports/experts.json)",
          "random-reports": "the random motion's reports", "demo-reports": "the demonstrations' reports",
          "dynamics-report": "the dynamics model's report (a file)", "translator-reports": "the translators' reports",
          "track-reports": "the re-executions' reports", "bc-reports": "the BC reports",
          "eval-reports": "the evaluations' reports and trials"}
"""The reports of the runs behind Table I; their bookkeeping (runs/) names the runs and their wall times."""


def bookkeeping(report_path: Path, pattern: str | None = None) -> list[Path]:
    """The bookkeeping files of the reports ``report_path/pattern`` (a folder), or of the report ``report_path``
    (a file); those missing left out."""
    books = stage.runs_path(report_path)
    if pattern is None:
        books, pattern = books.parent, books.name
    return sorted(books.glob(pattern))


def run() -> None:
    ap = stage.parser(__doc__, {**INPUTS, "out-dir": "where Table I, its plots and the stage times go"})
    args = ap.parse_args()
    p = stage.params(args.params)
    reports = args.out_dir
    trials = report.load_trials(args.eval_reports)
    expected = {(m, d, s) for m in p.grid.bc_methods for d in p.grid.demos for s in p.grid.seeds}
    keep = [(m, d, s) in expected for m, d, s in zip(trials.method, trials.demos, trials.seed)]
    trials = trials[keep]
    missing = expected - set(zip(trials.method, trials.demos, trials.seed))
    if missing:
        raise SystemExit(f"error: no evaluation for {sorted(missing)} in {args.eval_reports}; run `dvc repro`")
    run_rows = report.runs(trials)
    table = report.aggregate(trials)
    stage.write_csv(reports / "table1_runs.csv", run_rows.to_dict("records"))
    stage.write_csv(reports / "table1.csv", table.to_dict("records"))
    premise = stage.read_report(args.experts_summary)["programs_together_in_Y"]
    (reports / "table1.md").write_text(report.markdown(table, premise) + "\n" + report.differences_markdown(table))
    (reports / "table1.tex").write_text(report.latex(table))
    stage.write_csv(reports / "success_vs_demos.csv", run_rows[["method", "demos", "seed", "success_rate"]]
                    .to_dict("records"))
    png = report.plot(run_rows, table, reports / "success_vs_demos.png")
    curves_png = report.plot_translator_curves(args.translator_reports, reports / "translator_curves.png")
    diag = report.translator_diagnostics(args.translator_reports, args.track_reports)
    stage.write_csv(reports / "translator_diagnostics.csv", diag.to_dict("records"))
    # the top-level plots of dvc.yaml: one chart per quantity, the methods overlaid
    plots = reports / "plots"
    plots.mkdir(exist_ok=True)
    stage.write_csv(plots / "success_by_method.csv", report.success_by_method(table).to_dict("records"))
    stage.write_csv(plots / "bc_val_loss_by_method.csv",
                    report.curves_by_method(args.bc_reports, "val_loss").to_dict("records"))
    for name, column in (("translator_heldout_loss", "heldout/selection_loss"), ("translator_dyn_loss", "loss/dyn"),
                         ("translator_D_accuracy", "D/accuracy")):
        stage.write_csv(plots / f"{name}_by_method.csv",
                        report.curves_by_method(args.translator_reports, column).to_dict("records"))
    # the bookkeeping of the runs behind Table I, per stage: one run each, or one per seed
    books = {"train_experts": bookkeeping(args.expert_reports, "*_train.json"),
             "collect_random": bookkeeping(args.random_reports, "*.json"),
             "collect_demos": bookkeeping(args.demo_reports, "*.json"),
             "fit_dynamics": bookkeeping(args.dynamics_report),
             "train_translator": bookkeeping(args.translator_reports, "*.json"),
             "track_demos": bookkeeping(args.track_reports, "*.json"),
             "train_bc": bookkeeping(args.bc_reports, "*.json"),
             "evaluate": bookkeeping(args.eval_reports, "*.json")}
    times = report.stage_times(books)
    stage.write_csv(reports / "stage_times.csv", times.to_dict("records"))
    headline = report.headline(table)
    # one parent run per pipeline run: it carries the table and plot, and adopts the runs behind them
    children = [i for files in books.values() for f in files for i in stage.run_ids(json.loads(f.read_text()))]
    total_wall = float(times.total_s.sum())
    with stage.frame(None, "report", {"grid": p.grid.model_dump()}, tags={"pipeline_parent": "true"},
                     run_name=mlflow_runs.pipeline_run_name("pipeline")) as f:
        parent = f.run
        parent.metrics({f"{m}_d{d.removeprefix('d')}_success_rate": v
                        for m, row in headline.items() for d, v in row.items()})
        parent.metrics({"total_stage_wall_s": total_wall})
        for name in ("table1.md", "table1.csv", "table1.tex", "table1_runs.csv", "translator_diagnostics.csv",
                     "stage_times.csv"):
            parent.artifact(reports / name)
        parent.artifact(png)
        parent.artifact(curves_png)
        adopted = mlflow_runs.adopt_children(parent.run_id, children)
        # a reused run moves on to the newest parent run (MLflow keeps one parent per run); this list stays
        parent.dict({"runs": list(dict.fromkeys(children))}, "children.json")
        parent_id = parent.run_id
    mlflow_views.install()  # the UI's views of these runs (README: MLflow), after the parent run they show
    # not the frame's report: the parent run's id and the runs it adopted, written once the run has ended
    stage.write_report(reports / "table1.json", {**headline, "mlflow_parent_run_id": parent_id,
                                                 "mlflow_child_runs": adopted, "total_stage_wall_s": total_wall})
    print(report.markdown(table, premise))
    print(report.differences_markdown(table))
    print(times.to_string(index=False))


if __name__ == "__main__":
    stage.main(run)
