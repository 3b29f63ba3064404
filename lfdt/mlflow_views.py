"""Named views of the MLflow runs table: Table I's evaluation runs side by side, the translators with their
diagnostics, the BC runs, the pipeline parent runs.

MLflow keeps the columns a user picks in the browser only; a *shared view* (an experiment tag
``mlflow.sharedViewState.<key>``, opened with ``?viewStateShareKey=<key>``) travels with the tracking store instead.
``python -m lfdt.mlflow_views`` writes ours into the store (idempotent) and prints their URLs; ``make mlflow-ui`` does
it before starting the UI, and ``tools/mlflow_ui_check.py`` opens them in headless Chromium.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass, field

from lfdt import mlflow_runs

SHARED_VIEW_TAG = "mlflow.sharedViewState."
"""Prefix of the experiment tags MLflow's UI reads a shared runs-table view from (MLflow 3)."""
ML_WORKFLOW = "workflowType=machine_learning"
"""URL parameter that opens MLflow 3.17's UI on model training (runs), not on its GenAI overview: the UI's choice
between the two is a browser setting, and a fresh browser starts on GenAI whatever the experiment's kind tag says."""


def param(name: str) -> str:
    """The UI's key of a param column."""
    return f"params.`{name}`"


def metric(name: str) -> str:
    """The UI's key of a metric column."""
    return f"metrics.`{name}`"


@dataclass(frozen=True)
class View:
    """One runs-table view: which runs, which columns, in which order."""

    key: str
    """Share key, the ``viewStateShareKey`` of the URL."""
    title: str
    """What the view answers (printed beside its URL)."""
    stage: str
    """The ``lfdt.stage`` tag of the runs it shows."""
    columns: list[str]
    """Param and metric columns, in order (``param(...)``, ``metric(...)``)."""
    order_by: str = param("method")
    """Column the rows are sorted by."""
    ascending: bool = True
    extra_filter: str = ""
    """More of MLflow's search syntax, joined with AND."""
    metric_suffix: str = field(default="", compare=False)
    """If set, every metric of the shown runs whose name ends so is added as a column (the parent run's
    ``<method>_d<demos>_success_rate``, which depend on ``grid``)."""

    def search_filter(self) -> str:
        parts = [f"tags.`lfdt.stage` = '{self.stage}'"] + ([self.extra_filter] if self.extra_filter else [])
        return " AND ".join(parts)


IDS = [param("method"), param("demos"), param("seed")]

VIEWS = [
    View("lfdt-table1", "Table I: every evaluation run (method, demos, seed, success rate)", "evaluate",
         [*IDS, metric("success_rate"), metric("successes"), metric("trials")]),
    View("lfdt-translators", "translators: the kept checkpoint and its diagnostics", "train_translator",
         [*IDS, metric("selected_iteration"), metric("selected_heldout_loss"), metric("replay_success_rate"),
          metric("D/accuracy_translated_demos"), metric("dyn/missing_robot")]),
    View("lfdt-bc", "behaviour cloning: the kept iteration and its validation loss", "train_bc",
         # one policy for both arms (pi), or one per robot for BC without translation (pi_r1, pi_r2)
         [*IDS, *(metric(f"{pi}/{m}") for pi in ("pi", "pi_r1", "pi_r2")
                  for m in ("best_val_loss", "best_iteration"))]),
    View("lfdt-pipelines", "pipeline runs: Table I's rates per run of the pipeline", "report", [],
         order_by="attributes.start_time", ascending=False, metric_suffix="_success_rate"),
]
"""The views written into the tracking store, in the order they are printed."""


def _state(view: View, client, experiment_id: str) -> dict:
    columns = list(view.columns)
    if view.metric_suffix:
        runs = client.search_runs([experiment_id], view.search_filter(), max_results=50)
        found = sorted({k for r in runs for k in r.data.metrics if k.endswith(view.metric_suffix)})
        columns += [metric(k) for k in found]
    return {"selectedColumns": columns, "orderByKey": view.order_by, "orderByAsc": view.ascending,
            "searchFilter": view.search_filter()}


def install(experiment: str | None = None) -> tuple[str, dict[str, View]]:
    """Write every view into the current tracking store's experiment; returns the experiment id and the views by
    their URL fragment (``#/experiments/<id>/runs?viewStateShareKey=<key>&workflowType=machine_learning``)."""
    import mlflow

    exp_id = mlflow_runs.experiment_id(experiment)
    client = mlflow.MlflowClient()
    urls = {}
    for view in VIEWS:
        client.set_experiment_tag(exp_id, SHARED_VIEW_TAG + view.key, json.dumps(_state(view, client, exp_id)))
        urls[f"#/experiments/{exp_id}/runs?viewStateShareKey={view.key}&{ML_WORKFLOW}"] = view
    return exp_id, urls


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ui", default="http://127.0.0.1:5000", help="where the MLflow UI is (for the printed URLs)")
    args = ap.parse_args(argv)
    _, urls = install()
    exp_id = next(iter(urls)).split("/")[2] if urls else "?"
    print(f"MLflow views in {mlflow_runs.tracking_uri()}:")
    print(f"  the experiment's runs\n    {args.ui.rstrip('/')}/#/experiments/{exp_id}?{ML_WORKFLOW}")
    for frag, view in urls.items():
        print(f"  {view.title}\n    {args.ui.rstrip('/')}/{frag}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
