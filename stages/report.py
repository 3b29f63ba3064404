"""DVC stage: Table I (md, csv, tex), per-run CSV, the success-vs-demos plot, translator diagnostics, stage wall
times, and one MLflow parent run that carries them."""

import argparse
import json
from pathlib import Path

from lfdt import mlflow_runs, report, stage


def run() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    p = stage.params(args.params)
    reports = Path("reports")
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
    times = report.stage_times(reports)
    stage.write_csv(reports / "stage_times.csv", times.to_dict("records"))
    summary = {f"{r.method}/d{r.demos}/success_rate": r.success_rate for r in table.itertuples()}
    summary["total_stage_wall_s"] = float(times.total_s.sum())
    # one parent run per pipeline run: it carries the table and plot, and adopts the runs behind them
    children = []
    for sub in ("experts/*_train.json", "random/*.json", "demos/*.json", "dynamics.json"):
        for f in sorted(reports.glob(sub)):
            rid = json.loads(f.read_text()).get("mlflow_run_id")
            if rid:
                children.append(rid)
    for sub in ("translator/*.json", "track/*.json", "bc/*.json", "eval/*.json"):
        for f in sorted(reports.glob(sub)):
            for s in json.loads(f.read_text()).get("seeds", {}).values():
                if s.get("mlflow_run_id"):
                    children.append(s["mlflow_run_id"])
    with mlflow_runs.stage_run("report", {"grid": p.grid.model_dump()}, tags={"pipeline_parent": "true"},
                            run_name=mlflow_runs.pipeline_run_name("pipeline")) as parent:
        parent.metrics({k.replace("/", "_"): v for k, v in summary.items()})
        for f in ("table1.md", "table1.csv", "table1.tex", "table1_runs.csv", "translator_diagnostics.csv",
                  "stage_times.csv"):
            parent.artifact(reports / f)
        parent.artifact(png)
        parent.artifact(curves_png)
        adopted = mlflow_runs.adopt_children(parent.run_id, children)
        summary["mlflow_parent_run_id"] = parent.run_id
        summary["mlflow_child_runs"] = adopted
    stage.write_json(reports / "report.json", summary)
    print(report.markdown(table))
    print(times.to_string(index=False))


if __name__ == "__main__":
    stage.main(run)
