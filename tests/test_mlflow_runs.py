"""MLflow tracking: tags and params land in the run; experiment creation is safe under concurrency."""

import http.server
import subprocess
import sys
import textwrap

import mlflow
import pytest

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
    # what the numbers depend on besides code and params
    from lfdt import numerics

    assert tags["lfdt.numerics"] == numerics.mode() and tags["lfdt.cpu_model"] == numerics.cpu_model()
    assert tags["lfdt.cpu_isa"] in ("avx512", "avx2", "other")
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


def test_parent_run_adopts_its_children_and_refuses_a_missing_one(tmp_path, monkeypatch):
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    monkeypatch.setenv("MLFLOW_TRACKING_URI", uri)
    with mlflow_runs.stage_run("child", {}) as child:
        pass
    with mlflow_runs.stage_run("parent", {}) as parent:
        assert mlflow_runs.adopt_children(parent.run_id, [child.run_id, child.run_id]) == 1
        with pytest.raises(mlflow_runs.RunNotFound, match="0123456789abcdef"):
            mlflow_runs.adopt_children(parent.run_id, [child.run_id, "0123456789abcdef"])
    assert mlflow.MlflowClient(uri).get_run(child.run_id).data.tags["mlflow.parentRunId"] == parent.run_id


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


def test_unreachable_tracking_server_is_a_clear_error_within_seconds(tmp_path):
    import socket
    import time
    from pathlib import Path

    with socket.socket() as s:  # a port on 127.0.0.1 where nothing listens
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    root = Path(__file__).resolve().parents[1]
    env = {"PATH": "/usr/bin:/bin", "MLFLOW_TRACKING_URI": f"http://127.0.0.1:{port}", "HOME": str(tmp_path)}
    # what every stage does first: open its tracking run, through stage.main
    # the time counts from the stage's start after its imports (which a loaded machine slows, whatever the store)
    script = ("import time\nfrom lfdt import mlflow_runs, stage\n"
              "def run():\n    with mlflow_runs.stage_run('probe', {}):\n        pass\n"
              "print(time.monotonic(), flush=True)\nstage.main(run)\n")
    out = subprocess.run([sys.executable, "-c", script], cwd=root, env=env, capture_output=True, text=True,
                         timeout=120)
    took = time.monotonic() - float(out.stdout.split()[0])
    assert out.returncode == 2, out.stderr[-2000:]
    assert f"MLFLOW_TRACKING_URI=http://127.0.0.1:{port} does not answer" in out.stderr
    assert "Traceback" not in out.stderr and took < 15, took


def test_a_killed_stage_run_is_marked_killed_when_the_stage_next_starts(tmp_path, monkeypatch):
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    script = textwrap.dedent(f"""
        import os
        os.environ["MLFLOW_TRACKING_URI"] = {uri!r}
        from lfdt import mlflow_runs
        with mlflow_runs.stage_run("victim", {{}}, run_name="victim-s0") as run:
            print(run.run_id, flush=True)
            os.kill(os.getpid(), 9)
    """)
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    dead_id = out.stdout.strip()
    client = mlflow.MlflowClient(uri)
    assert client.get_run(dead_id).info.status == "RUNNING"  # nobody ended it
    monkeypatch.setenv("MLFLOW_TRACKING_URI", uri)
    with mlflow_runs.stage_run("victim", {}, run_name="victim-s0") as run:
        new_id = run.run_id
    assert client.get_run(dead_id).info.status == "KILLED"
    assert client.get_run(new_id).info.status == "FINISHED"


def test_temp_files_of_a_killed_writer_are_removed_on_the_next_write(tmp_path):
    from lfdt import stage

    ended = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    dead = tmp_path / f".m.json.tmp-{ended.stdout.strip()}"  # what a writer killed mid-write leaves behind
    dead.write_text("half")
    stage.write_json(tmp_path / "m.json", {"a": 1})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.json"]


def test_commit_is_dirty_only_when_source_differs(tmp_path):
    def git(*args):
        subprocess.run(["git", *args], cwd=tmp_path, check=True, capture_output=True)

    git("init", "-q")
    for name in ("dvc.yaml", "lfdt/a.py", "reports/m.json", "dvc.lock"):
        (tmp_path / name).parent.mkdir(exist_ok=True)
        (tmp_path / name).write_text("1\n")
    git("add", ".")
    git("-c", "user.email=t@t", "-c", "user.name=t", "commit", "-qm", "init")
    (tmp_path / "reports/m.json").unlink()  # DVC removes a stage's outputs before running it
    (tmp_path / "dvc.lock").write_text("2\n")
    assert not mlflow_runs.git_commit(tmp_path).endswith("-dirty")
    (tmp_path / "lfdt/a.py").write_text("2\n")
    assert mlflow_runs.git_commit(tmp_path).endswith("-dirty")


def test_a_refused_duplicate_experiment_tag_is_fine_when_the_tag_holds(tmp_path, monkeypatch):
    """Two stages on a fresh tracking server both set the experiment's kind tag; the server's database refuses the
    second insert. That is no error when the tag now holds our value, and stays one when it does not."""
    from mlflow.exceptions import MlflowException

    monkeypatch.setenv("MLFLOW_TRACKING_URI", f"sqlite:///{tmp_path / 'mlflow.db'}")
    client = mlflow.MlflowClient(f"sqlite:///{tmp_path / 'mlflow.db'}")
    exp = client.create_experiment("lfdt")
    real = mlflow.MlflowClient.set_experiment_tag

    def racing(self, experiment_id, key, value):  # the other stage's insert lands first, ours is refused
        real(self, experiment_id, key, value)
        raise MlflowException("duplicate key value violates unique constraint \"experiment_tag_pk\"")

    monkeypatch.setattr(mlflow.MlflowClient, "set_experiment_tag", racing)
    assert mlflow_runs.experiment_id("lfdt") == exp

    def refused(self, experiment_id, key, value):
        raise MlflowException("permission denied")

    client.delete_experiment_tag(exp, mlflow_runs.EXPERIMENT_KIND_TAG)
    monkeypatch.setattr(mlflow.MlflowClient, "set_experiment_tag", refused)
    with pytest.raises(MlflowException, match="permission denied"):
        mlflow_runs.experiment_id("lfdt")


def test_a_store_whose_path_has_a_percent_escape_keeps_its_lock_and_artifacts_beside_it(tmp_path, monkeypatch):
    """``sqlite:///.../my%20dir/mlflow.db`` is a database in 'my dir' (SQLAlchemy decodes the path): the experiment's
    lock and artifact folder sit there too, none of them in a folder 'my%20dir' (MLflow itself makes that one, empty,
    as the database's parent before SQLAlchemy decodes the path)."""
    (tmp_path / "my dir").mkdir()
    monkeypatch.setenv("MLFLOW_TRACKING_URI", f"sqlite:///{tmp_path}/my%20dir/mlflow.db")
    exp = mlflow_runs.experiment_id("lfdt")
    assert (tmp_path / "my dir" / "mlflow.db").is_file()
    assert (tmp_path / "my dir" / "mlflow.db.lock").is_file()
    location = mlflow.MlflowClient().get_experiment(exp).artifact_location
    assert location == (tmp_path / "my dir" / "mlartifacts").as_uri()
    assert not any((tmp_path / "my%20dir").glob("**/*"))


class _Health(http.server.BaseHTTPRequestHandler):
    def do_GET(self):  # noqa: N802 - http.server's name
        self.send_response(200 if self.path == "/health" else 404)
        self.end_headers()
        self.wfile.write(b"OK")

    def log_message(self, *args):
        pass


def test_tracking_uris_users_write_are_accepted(tmp_path):
    """Spellings MLflow accepts pass the check: Databricks by name, a path with %20, a database on a local socket,
    a server with basic auth in the URL (user:password@ is not part of the address)."""
    import threading

    from lfdt import mlflow_runs

    (tmp_path / "my dir").mkdir()
    server = http.server.HTTPServer(("127.0.0.1", 0), _Health)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        for uri in ("databricks", "databricks-uc", f"sqlite:///{tmp_path}/my%20dir/mlflow.db",
                    "postgresql+psycopg2:///mlflow", "postgresql+psycopg2://lfdt@/mlflow?host=/var/run/postgresql",
                    f"http://lfdt:secret@127.0.0.1:{server.server_port}",
                    f"http://127.0.0.1:{server.server_port}/prefix/"):
            mlflow_runs.check_tracking_uri(uri)
    finally:
        server.shutdown()
        server.server_close()
