"""Named views of the MLflow runs table: Table I's evaluation runs side by side, the translators with their
diagnostics, the BC runs, the pipeline parent runs, the real-robot tasks.

MLflow keeps the columns a user picks in the browser only; a *shared view* (an experiment tag
``mlflow.sharedViewState.<key>``, opened with ``?viewStateShareKey=<key>``) travels with the tracking store instead.
``python -m lfdt.mlflow_views`` writes ours into the store (idempotent) and prints their URLs; ``make mlflow-ui`` does
it before starting the UI, and ``tools/mlflow_ui_check.py`` opens them in headless Chromium.
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass

from lfdt import mlflow_runs
from lfdt.inputs import ArgumentParser, one_line_errors

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
    parent_stage: str | None = "report"
    """Only the children of this stage's newest run (the parent run of one run of the pipeline or of the twin);
    None: every run of ``stage``."""
    metric_suffix: str = ""
    """If set, every metric of the shown runs whose name ends so is added as a column (the parent run's
    ``<method>_d<demos>_success_rate``, which depend on ``grid``)."""

    def search_filter(self, parent: str | None = None) -> str:
        """MLflow's search filter of the view; with ``parent``, only that parent run's children (the runs behind
        the current Table I, not those of earlier runs of the pipeline)."""
        parts = [f"tags.`lfdt.stage` = '{self.stage}'"] + ([self.extra_filter] if self.extra_filter else [])
        if parent and self.parent_stage:
            parts.append(f"tags.`mlflow.parentRunId` = '{parent}'")
        return " AND ".join(parts)

    def search_order(self) -> str:
        """The view's sort order in MLflow's search syntax (``params.method ASC``)."""
        return f"{self.order_by.replace('`', '')} {'ASC' if self.ascending else 'DESC'}"


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
         order_by="attributes.start_time", ascending=False, parent_stage=None, metric_suffix="_success_rate"),
    View("lfdt-twin", "the real-robot tasks (twin or robots): both methods' success per task", "twin_evaluate",
         [param("twin.backend"), param("twin.seeds"), param("twin.trials"),
          *(metric(f"{m}/{k}") for m in ("lfdt", "bc_no_translation") for k in ("success_rate", "successes"))],
         order_by="attributes.run_name", parent_stage="twin_report"),
]
"""The views written into the tracking store, in the order they are printed."""


def _state(view: View, client, experiment_id: str, parent: str | None) -> dict:
    columns = list(view.columns)
    if view.metric_suffix:
        runs = client.search_runs([experiment_id], view.search_filter(parent), max_results=50)
        found = sorted({k for r in runs for k in r.data.metrics if k.endswith(view.metric_suffix)})
        columns += [metric(k) for k in found]
    return {"selectedColumns": columns, "orderByKey": view.order_by, "orderByAsc": view.ascending,
            "searchFilter": view.search_filter(parent)}


def latest_run(client, experiment_id: str, stage: str = "report") -> str | None:
    """Id of the newest run of a stage (``report``: the pipeline's parent run; ``twin_report``: the twin's), or None
    before the first."""
    runs = client.search_runs([experiment_id], f"tags.`lfdt.stage` = '{stage}'", max_results=1,
                              order_by=["attributes.start_time DESC"])
    return runs[0].info.run_id if runs else None


def install(experiment: str | None = None) -> tuple[str, dict[str, tuple[View, dict]]]:
    """Write every view into the current tracking store's experiment, each showing the runs behind the newest
    pipeline (or twin) run; returns the experiment id and, by URL fragment
    (``#/experiments/<id>/runs?viewStateShareKey=<key>&workflowType=machine_learning``), each view and its state."""
    import mlflow

    exp_id = mlflow_runs.experiment_id(experiment)
    client = mlflow.MlflowClient()
    parents = {st: latest_run(client, exp_id, st) for st in {v.parent_stage for v in VIEWS if v.parent_stage}}
    urls = {}
    for view in VIEWS:
        state = _state(view, client, exp_id, parents.get(view.parent_stage))
        client.set_experiment_tag(exp_id, SHARED_VIEW_TAG + view.key, json.dumps(state))
        urls[f"#/experiments/{exp_id}/runs?viewStateShareKey={view.key}&{ML_WORKFLOW}"] = (view, state)
    return exp_id, urls


def main(argv: list[str] | None = None) -> int:
    ap = ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ui", default="http://127.0.0.1:5000", help="where the MLflow UI is (for the printed URLs)")
    ap.add_argument("--port-free", action="store_true",
                    help="first check that nothing listens on --ui's port here (make mlflow-ui starts the UI there "
                         "next: the URLs would otherwise open whatever already serves it)")
    args = ap.parse_args(argv)

    def run() -> int:
        if args.port_free:
            port_free(args.ui)
        return _report(*install(), args.ui)

    # the store or LFDT_MLFLOW_EXPERIMENT: one line naming it, as a stage says it
    return one_line_errors(run, "the views already saved stay; rerun to add the rest")


def port_free(ui: str) -> None:
    """InputError when a server already listens on ``ui``'s host and port on this machine (say, another project's
    ``make mlflow-ui``): the UI about to start there could not bind, and the printed URLs would open the other one."""
    import errno
    import socket

    from lfdt.errors import InputError
    from lfdt.reach import host_port

    host, port = host_port(ui, default_port=80)
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as s:
        # as the UI's server binds: a connection of a UI stopped a moment ago (TIME_WAIT) does not hold the port
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host, port))
        except OSError as e:
            if e.errno != errno.EADDRINUSE:
                raise
            raise InputError(f"{host}:{port} is in use (another `make mlflow-ui`?): stop that server, or serve this "
                             f"one on another port: make mlflow-ui UI_PORT={port + 1}") from None


def _report(exp_id: str, urls: dict, ui: str) -> int:
    print(f"MLflow views in {mlflow_runs.tracking_uri()}:")
    print(f"  the experiment's runs\n    {ui.rstrip('/')}/#/experiments/{exp_id}?{ML_WORKFLOW}")
    for frag, (view, _) in urls.items():
        print(f"  {view.title}\n    {ui.rstrip('/')}/{frag}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
