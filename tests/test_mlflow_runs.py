"""MLflow tracking: tags and params land in the run; experiment creation is safe under concurrency."""

import subprocess
import sys
import textwrap

import mlflow

from lfdt import mlflow_runs


def test_stage_run_logs_params_metrics_tags(tmp_path, monkeypatch):
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    monkeypatch.setenv("MLFLOW_TRACKING_URI", uri)
    monkeypatch.setenv("DVC_EXP_NAME", "exp-smoke")
    with mlflow_runs.stage_run("unit", {"a": {"b": 1, "c": [1, 2]}}, tags={"seed": 3, "domain": "Y"}) as run:
        for step in range(2500):  # more than one batch
            run.metrics({"loss": 1.0 / (step + 1)}, step=step)
        run_id = run.run_id
    client = mlflow.MlflowClient(uri)
    r = client.get_run(run_id)
    assert r.info.status == "FINISHED"
    assert r.data.params == {"a.b": "1", "a.c": "[1, 2]"}
    tags = r.data.tags
    assert tags["lfdt.stage"] == "unit" and tags["lfdt.seed"] == "3" and tags["lfdt.domain"] == "Y"
    assert tags["dvc.exp_name"] == "exp-smoke"
    assert {"version.mujoco", "version.torch", "version.stable-baselines3", "version.gymnasium"} <= set(tags)
    assert "mlflow.source.git.commit" in tags
    assert len(client.get_metric_history(run_id, "loss")) == 2500


def test_failed_stage_marks_run_failed(tmp_path, monkeypatch):
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    monkeypatch.setenv("MLFLOW_TRACKING_URI", uri)
    try:
        with mlflow_runs.stage_run("boom", {}) as run:
            run_id = run.run_id
            raise RuntimeError("boom")
    except RuntimeError:
        pass
    assert mlflow.MlflowClient(uri).get_run(run_id).info.status == "FAILED"


def test_two_stages_starting_at_once_share_one_experiment(tmp_path):
    script = textwrap.dedent(f"""
        import os
        os.environ["MLFLOW_TRACKING_URI"] = "sqlite:///{tmp_path / 'mlflow.db'}"
        from lfdt import mlflow_runs
        with mlflow_runs.stage_run("race", {{"x": 1}}) as run:
            run.metrics({{"m": 1.0}})
        print(mlflow_runs.experiment_id())
    """)
    procs = [subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for _ in range(3)]
    outs = [p.communicate(timeout=180) for p in procs]
    assert all(p.returncode == 0 for p in procs), [o[1][-2000:] for o in outs]
    assert len({o[0].strip() for o in outs}) == 1
    client = mlflow.MlflowClient(f"sqlite:///{tmp_path / 'mlflow.db'}")
    exp = client.get_experiment_by_name("lfdt")
    assert len(client.search_runs([exp.experiment_id])) == 3
