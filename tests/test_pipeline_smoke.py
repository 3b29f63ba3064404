"""The whole DVC DAG on tiny params: every stage runs, every artifact has its schema, reruns are incremental."""

import csv
import json
import os
import re
import signal
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest
import smoke
import yaml

from lfdt import data, layout, methods, stage
from lfdt.tasks.box_push import columns as box_columns

# with `pytest -n` (make test) these tests run on one worker, one after the other (later ones change the project);
# the sweep's group runs on the other worker meanwhile
pytestmark = pytest.mark.xdist_group("smoke_project")

_dvc = smoke.dvc


@pytest.fixture(scope="module")
def project(smoke_project):
    """A copy of the project with the smoke params, after one full `dvc repro` (tests/conftest.py)."""
    return smoke_project.root, smoke_project.output


METHODS = tuple(methods.METHODS)
TRANSLATORS = tuple(methods.translator_methods())
SEEDS = (0, 1)


def test_every_stage_ran(project):
    _, out = project
    stages = ["preflight", "train_experts", "collect_random", "collect_demos", "fit_dynamics", "select_demos@3",
              "track_demos@3", "report", "twin_report", "register_policies"]
    stages += [f"{s}@{t}" for s in ("twin_collect", "twin_train", "twin_evaluate")
               for t in ("block_push", "peg_insertion")]
    stages += [f"train_translator@{m}-3" for m in TRANSLATORS]
    stages += [f"bc_evaluate@{m}-3" for m in METHODS]
    for name in stages:
        assert f"'{name}'" in out


def test_no_training_checkpoint_outlives_its_stage(project):
    """The resumable states of experts and translators are removed once their stage's models are saved."""
    root, _ = project
    left = [str(f.relative_to(root)) for f in (root / "checkpoints").rglob("*") if f.is_file()]
    assert not left, left


def test_artifact_schemas(project):
    dst, _ = project
    for domain in layout.DOMAINS:
        meta = data.check_transitions(dst / f"data/random/{domain}.parquet", "random", domain, box_columns.BOX_PUSH)
        assert data.read_transitions(dst / f"data/random/{domain}.parquet").shape[0] == 3000
        assert meta["random"]["transitions"] == 3000
    for pairing in layout.PAIRINGS:
        data.check_transitions(dst / f"data/demos/{pairing}.parquet", "demos", pairing, box_columns.BOX_PUSH)
        df = data.read_transitions(dst / f"data/demos/{pairing}.parquet")
        assert df.episode_index.nunique() == 4
        cfg = json.loads((dst / f"models/experts/{pairing}/config.json").read_text())
        assert cfg["experts"]["total_timesteps"] == 800
        assert (dst / f"models/experts/{pairing}/policy.pt").exists()


def test_metrics_files(project):
    dst, _ = project
    summary = json.loads((dst / "reports/experts.json").read_text())
    assert summary["protocol"] == "programmed_robot"
    assert 0 <= summary["programs_together_in_Y"]["success_rate"] <= 1
    for pairing in layout.PAIRINGS:
        entry = summary[pairing]
        assert entry["episodes"] == 3 and 0 <= entry["success_rate"] <= 1
        assert entry["mean_demo_length"] > 0 and entry["demo_attempts"] == 4
    for domain in layout.DOMAINS:
        assert json.loads((dst / f"reports/random/{domain}.json").read_text())["transitions"] == 3000
    curve = (dst / "reports/experts/R1H_curve.csv").read_text().splitlines()
    assert curve[0] == "timesteps,success_rate,episode_return" and len(curve) == 5
    assert (dst / "mlflow.db").exists()


def test_second_half_artifacts(project):
    dst, _ = project
    dyn = json.loads((dst / "reports/dynamics.json").read_text())
    assert {"forward_ratio", "inverse_ratio", "forward_mse", "inverse_mse"} <= set(dyn)
    assert (dst / "models/dynamics/dynamics.pt").exists() and (dst / "models/dynamics/dynamics.json").exists()
    for m in TRANSLATORS:
        tr = json.loads((dst / f"reports/translator/{m}-d3.json").read_text())
        assert set(tr["seeds"]) == {str(s) for s in SEEDS}
        # held-out losses (every select_every) and diagnostics (every log_every) share one column set
        with open(dst / f"reports/translator/{m}-d3_curve.csv", newline="") as fh:
            rows = list(csv.DictReader(fh))
        assert {"loss/dyn", "heldout/selection_loss"} <= set(rows[0])
        assert {r["iteration"] for r in rows if r["heldout/selection_loss"]} == {"30", "60"}
        for seed in SEEDS:
            path = dst / f"data/bc_train/{m}-d3/s{seed}/translated.parquet"
            meta = data.read_metadata(path)
            assert meta["kind"] == "translated" and meta["method"] == m and meta["demos"] == 3
            assert meta["seed"] == seed
            df = data.read_transitions(path)
            assert df.episode_index.nunique() == 6 and set(df.source_pairing) == set(layout.PAIRINGS)
            want = [layout.STATE_PREFIX + c for c in box_columns.state_columns("Y")]
            want += [layout.ACTION_PREFIX + c for c in box_columns.action_columns("Y")]
            assert set(want) <= set(df.columns) and df[want].notna().all().all()
            d = tr["seeds"][str(seed)]
            assert d["replay_box_position_error_m"] >= 0 and 0 <= d["final/D/accuracy"] <= 1
            # the diagnostics the README shows
            assert {"dyn/real_robot", "dyn/missing_robot", "dyn/object", "D/accuracy_translated_demos",
                    "D/accuracy_translated_random", "labels/real_robot_rmse", "fk/missing_robot_ee_error_m",
                    "replay_success_rate", "selected_iteration"} <= set(d)
            assert d["fk/missing_robot_ee_error_m"] < 1e-5  # translator.kinematics: forward
    track = json.loads((dst / "reports/track/lfdt_track-d3.json").read_text())
    for seed in SEEDS:
        assert track["seeds"][str(seed)]["executions"] == 6
        meta = data.read_metadata(dst / f"data/bc_train/lfdt_track-d3/s{seed}/executed.parquet")
        assert meta["kind"] == "executed"
    for m in METHODS:
        ev = json.loads((dst / f"reports/eval/{m}-d3.json").read_text())
        trials = (dst / f"reports/eval/{m}-d3_trials.csv").read_text().splitlines()
        assert len(trials) == 1 + 3 * len(SEEDS)
        for seed in SEEDS:
            assert ev["seeds"][str(seed)]["trials"] == 3
            assert (dst / f"reports/videos/{m}-d3/s{seed}/trial00.mp4").stat().st_size > 1000
            assert list((dst / f"models/bc/{m}-d3/s{seed}").glob("*.pt"))
    assert len(list((dst / "models/bc/bc_no_translation-d3/s0").glob("*.pt"))) == 2
    runs = (dst / "reports/table1_runs.csv").read_text().splitlines()
    assert runs[0].startswith("method,demos,seed,trials,successes,success_rate,success_rate_first20")
    assert len(runs) == 1 + len(METHODS) * len(SEEDS)
    assert any(r.startswith("lfdt_track,") for r in runs)
    table = (dst / "reports/table1.csv").read_text().splitlines()
    assert len(table) == 1 + len(METHODS)
    md = (dst / "reports/table1.md").read_text()
    assert "LfDT" in md and "paper" in md and "first 20" in md
    assert (dst / "reports/table1.tex").read_text().startswith("\\begin{tabular}")
    assert (dst / "reports/success_vs_demos.png").stat().st_size > 5000
    assert (dst / "reports/translator_curves.png").stat().st_size > 5000
    assert (dst / "reports/translator_diagnostics.csv").read_text().startswith("method,demos,seeds")
    rep = json.loads((dst / "runs/table1.json").read_text())
    per_seed = len(TRANSLATORS) + 1 + 2 * len(METHODS)  # translators, re-execution, BC and evaluation
    assert rep["mlflow_child_runs"] == 2 + 3 + 2 + 1 + per_seed * len(SEEDS)  # every run behind the table
    headline = json.loads((dst / "reports/table1.json").read_text())
    assert set(headline) == set(METHODS) and all(set(v) == {"d3", "d3_path"} for v in headline.values())
    rows = {r.split(",")[0]: r.split(",") for r in table[1:]}
    header = table[0].split(",")
    for m in METHODS:
        assert headline[m]["d3"] == round(float(rows[m][header.index("success_rate")]), 4)
        assert headline[m]["d3_path"] == round(float(rows[m][header.index("path_success_rate")]), 4)
        # the path rule asks more than the end-state rule: never more successes
        assert int(rows[m][header.index("path_successes")]) <= int(rows[m][header.index("successes")])


def test_a_translators_diagnostics_are_recomputed_bit_for_bit(project, tmp_path):
    """tools/check_diagnostics.py recomputes a seed's translator diagnostics from its saved translators and finds the
    report's values; a report value changed by one bit is named."""
    dst, _ = project
    tool = [sys.executable, str(smoke.ROOT / "tools" / "check_diagnostics.py"), "--method", "lfdt", "--demos", "3",
            "--seed", "0"]
    ok = subprocess.run([*tool, "--root", str(dst)], capture_output=True, text=True, timeout=300)
    assert ok.returncode == 0 and "match" in ok.stdout, ok.stdout + ok.stderr
    other = tmp_path / "p"
    (other / "reports" / "translator").mkdir(parents=True)
    for name in ("params.yaml", "dvc.yaml", "models", "data"):
        (other / name).symlink_to(dst / name)
    rep = json.loads((dst / "reports/translator/lfdt-d3.json").read_text())
    rep["seeds"]["0"]["diag/hand_across_m"] = float.fromhex("0x1p-52") + rep["seeds"]["0"]["diag/hand_across_m"]
    (other / "reports/translator/lfdt-d3.json").write_text(json.dumps(rep))
    bad = subprocess.run([*tool, "--root", str(other)], capture_output=True, text=True, timeout=300)
    assert bad.returncode == 1 and "DIFFERS diag/hand_across_m" in bad.stdout, bad.stdout + bad.stderr


def test_metrics_hold_no_bookkeeping(project):
    """Run ids, wall times and speeds live in runs/, never in a report (an identical rerun must not change one);
    every report has its bookkeeping twin. `dvc metrics show` lists the three headline files alone."""
    dst, _ = project

    def keys(obj):
        if isinstance(obj, dict):
            for k, v in obj.items():
                yield k
                yield from keys(v)

    shown = json.loads(_dvc(["metrics", "show", "--json"], dst))
    assert {f for rev in shown.values() for f in rev.get("data", {})} == \
        {"reports/table1.json", "reports/twin.json", "reports/experts.json"}
    # reports/fingerprint.json: hashes of the numeric code paths, no stage report (no run, no wall time)
    files = sorted(p.relative_to(dst).as_posix() for p in (dst / "reports").rglob("*.json")
                   if p.name != "fingerprint.json")
    assert "reports/eval/lfdt-d3.json" in files and len(files) > 20
    for f in files:
        bad = [k for k in keys(json.loads((dst / f).read_text())) if stage.is_bookkeeping(k)]
        assert not bad, f"{f} holds bookkeeping keys {bad}"
        assert (dst / stage.runs_path(f)).is_file(), f
    merged = stage.read_report(dst / "reports/eval/lfdt-d3.json")
    assert all(s["mlflow_run_id"] and "success_rate" in s for s in merged["seeds"].values())
    assert merged["stage_wall_s"] > 0 and merged["method"] == "lfdt"


def test_overlay_plots(project):
    """dvc.yaml's top-level plots put every method in one chart per quantity."""
    dst, _ = project
    shown = json.loads(_dvc(["plots", "show", "--json"], dst))["data"]
    for name, want in (("success_by_method", METHODS), ("bc_val_loss_by_method", METHODS),
                       ("translator_heldout_loss_by_method", TRANSLATORS),
                       ("translator_dyn_loss_by_method", TRANSLATORS)):
        spec = shown[f"reports/plots/{name}.csv"][0]["content"]
        assert {v["field"] for v in spec["data"]["values"]} == set(want), name


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _post(url: str, body: dict) -> dict:
    req = urllib.request.Request(url, data=json.dumps(body).encode(), headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(req, timeout=10) as r:
        return json.loads(r.read())


def _tag(run: dict, key: str) -> str | None:
    return {t["key"]: t["value"] for t in run["data"].get("tags", [])}.get(key)


def test_mlflow_server_serves_the_pipeline_runs(project):
    dst, _ = project
    port = _free_port()
    server = subprocess.Popen(
        [str(Path(sys.executable).parent / "mlflow"), "server", "--backend-store-uri", f"sqlite:///{dst / 'mlflow.db'}",
         "--host", "127.0.0.1", "--port", str(port), "--workers", "1"],
        cwd=dst, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    base = f"http://127.0.0.1:{port}/api/2.0/mlflow"
    try:
        deadline = time.time() + 90
        while True:
            try:
                exp = _post(f"{base}/experiments/search", {"max_results": 10})
                break
            except (urllib.error.URLError, ConnectionError):
                assert server.poll() is None, "mlflow server exited"
                assert time.time() < deadline, "mlflow server did not answer in 90 s"
                time.sleep(0.5)
        ids = [e["experiment_id"] for e in exp["experiments"] if e["name"] == "lfdt"]
        assert ids, exp
        # a model-training experiment: MLflow's UI opens it on its runs table
        lfdt_exp = next(e for e in exp["experiments"] if e["name"] == "lfdt")
        assert {t["key"]: t["value"] for t in lfdt_exp.get("tags", [])}["mlflow.experimentKind"] == \
            "custom_model_development"
        runs = _post(f"{base}/runs/search", {"experiment_ids": ids, "max_results": 500})["runs"]
        by_stage = {}
        for r in runs:
            tags = {t["key"]: t["value"] for t in r["data"].get("tags", [])}
            by_stage.setdefault(tags.get("lfdt.stage"), []).append(r)
        assert {"train_experts", "collect_random", "collect_demos", "fit_dynamics", "train_translator", "train_bc",
                "evaluate", "report"} <= set(by_stage)
        ev = by_stage["evaluate"]
        assert len(ev) == len(METHODS) * len(SEEDS)
        for r in ev:  # same param and metric names across methods, so the UI can compare them
            params = {p["key"] for p in r["data"]["params"]}
            metrics = {m["key"] for m in r["data"]["metrics"]}
            assert {"method", "demos", "seed", "evaluation.trials"} <= params
            assert {"success_rate", "successes", "trials"} <= metrics
            assert not {"demos", "seed"} & metrics  # identifiers are params, never metrics
            name = r["info"]["run_name"]  # the distinguishing part first, as the UI truncates names
            assert re.fullmatch(r"[a-z_]+-d\d+-s\d+ evaluate", name), name
        parents = [r for r in by_stage["report"]]
        assert parents and all(r["info"]["run_name"].startswith("pipeline ") for r in parents)
        twin = by_stage["twin_report"]
        assert twin and all(r["info"]["run_name"].startswith("twin ") for r in twin)
        twin_children = [r for r in runs if {t["key"]: t["value"] for t in r["data"].get("tags", [])}
                         .get("mlflow.parentRunId") == twin[-1]["info"]["run_id"]]
        assert {_tag(r, "lfdt.stage") for r in twin_children} == {"twin_collect", "twin_train", "twin_evaluate"}
        tr = by_stage["train_translator"][0]
        url = f"{base}/metrics/get-history?run_id={tr['info']['run_id']}&metric_key=D/accuracy"
        with urllib.request.urlopen(url, timeout=10) as resp:
            assert len(json.loads(resp.read())["metrics"]) == 3  # 60 iterations, logged every 20
    finally:
        os.killpg(server.pid, signal.SIGTERM)
        try:
            server.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(server.pid, signal.SIGKILL)
            server.wait()


def test_twin_pipeline_outputs(project):
    dst, _ = project
    runs = (dst / "reports/twin_runs.csv").read_text().splitlines()
    assert runs[0] == "task,method,seed,trial,success"
    rows = [r.split(",") for r in runs[1:]]
    assert {(r[0], r[1], r[2]) for r in rows} == {(t, m, s) for t in ("block_push", "peg_insertion")
                                                  for m in ("bc_no_translation", "lfdt") for s in ("0", "1")}
    assert len(rows) == 2 * 2 * 2 * 2 and {r[4] for r in rows} <= {"True", "False"}
    md = (dst / "reports/twin.md").read_text()
    assert "paper (real robots)" in md and "10/10" in md and "8/10" in md and "seeds 0, 1" in md
    for task in ("block_push", "peg_insertion"):
        for seed in (0, 1):
            files = sorted((dst / f"data/twin/{task}/s{seed}/demos_R1H").glob("episode_*.parquet"))
            assert len(files) == 2
            models = dst / f"models/twin/{task}/s{seed}"
            assert (models / "lfdt").is_dir() and (models / "translator.pt").exists()
        # each seed is its own run: its own data
        assert (dst / f"data/twin/{task}/s0/random_Y/episode_000000.parquet").read_bytes() != \
               (dst / f"data/twin/{task}/s1/random_Y/episode_000000.parquet").read_bytes()


def test_every_policy_is_a_registered_mlflow_model(project, tmp_path):
    """reports/models.csv names a registered model per trained policy; loaded by its URI it acts like the policy in
    models/ (the same bits), `mlflow models predict` answers its saved observation, and the twin's deploy takes it."""
    import mlflow
    import numpy as np

    from lfdt import bc, policy_models
    from lfdt.tasks import registry

    dst, _ = project
    rows = list(csv.DictReader((dst / "reports/models.csv").open()))
    table1 = {(r["method"], r["seed"]) for r in rows if r["task"] == "box_push"}
    twin = {(r["task"], r["method"], r["seed"]) for r in rows if r["task"] != "box_push"}
    assert table1 == {(m, str(s)) for m in METHODS for s in SEEDS}
    assert twin == {(t, m, str(s)) for t in ("block_push", "peg_insertion") for m in ("bc_no_translation", "lfdt")
                    for s in SEEDS}
    env = {**os.environ, "MLFLOW_TRACKING_URI": f"sqlite:///{dst / 'mlflow.db'}"}
    os.environ["MLFLOW_TRACKING_URI"] = env["MLFLOW_TRACKING_URI"]
    try:
        for task, method, folder in (("box_push", "bc_no_translation", "models/bc/bc_no_translation-d3/s1"),
                                     ("block_push", "lfdt", "models/twin/block_push/s1/lfdt")):
            uri = f"models:/{policy_models.registered_name(task, method, 3 if task == 'box_push' else None)}@seed1"
            assert uri in {r["uri"] for r in rows}
            bounds = (-1.0, 1.0) if task == "box_push" else None
            saved, _ = bc.BCPolicy.load(dst / folder, registry.get(task).layout, bounds)
            loaded = policy_models.policy_from_uri(uri, task, method)
            obs = policy_models.input_example(task).to_numpy()[0]
            assert np.array_equal(loaded(obs), saved(obs)), f"{uri} acts otherwise than {folder}"
            with pytest.raises(ValueError, match="not the"):
                policy_models.policy_from_uri(uri, task, "lfdt_no_id")
            model = mlflow.models.get_model_info(uri)
            assert model.signature.inputs.input_names() == registry.get(task).layout.state_columns("Y")
            example = Path(mlflow.artifacts.download_artifacts(f"{uri}/serving_input_example.json",
                                                               dst_path=str(tmp_path / task)))
            out = subprocess.run([str(Path(sys.executable).parent / "mlflow"), "models", "predict", "-m", uri,
                                  "-i", str(example), "-t", "json", "--env-manager", "local"], env=env, cwd=dst,
                                 capture_output=True, text=True, timeout=300)
            assert out.returncode == 0, out.stderr[-2000:]
            pred = json.loads(out.stdout[out.stdout.index('{"predictions"'):])["predictions"][0]
            assert list(pred) == registry.get(task).layout.action_columns("Y")
            np.testing.assert_allclose(list(pred.values()), saved(obs), atol=1e-5)
    finally:
        os.environ.pop("MLFLOW_TRACKING_URI")
    log = tmp_path / "deploy.csv"
    out = subprocess.run([sys.executable, "-m", "lfdt.robot", "deploy", "--sim", "--task", "block_push", "--method",
                          "lfdt", "--models", "models:/block_push.lfdt@seed1", "--trials", "2", "--log", str(log)],
                         env=env, cwd=dst, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert len(log.read_text().splitlines()) == 3


def test_an_edit_of_the_gan_reruns_training_never_data_collection(project):
    """lfdt/translation/training.py is the translator's training code: the stages that train translators go stale, the
    twin's data collection and the demonstrations do not, nor the re-execution of translations (track_demos applies
    translators and does not run their training code)."""
    dst, _ = project
    gan = dst / "lfdt/translation/training.py"
    original = gan.read_bytes()
    try:
        gan.write_bytes(original + b"\n# an edit\n")
        stale = set(json.loads(_dvc(["status", "--json"], dst)))
    finally:
        gan.write_bytes(original)
    assert {"twin_train@block_push", "train_translator@lfdt-3"} <= stale
    assert not stale & {"twin_collect@block_push", "twin_collect@peg_insertion", "collect_demos", "collect_random",
                        "train_experts", "fit_dynamics", "track_demos@3"}, sorted(stale)


def test_second_repro_does_nothing_and_param_change_reruns_only_dependents(project):
    dst, _ = project
    out = _dvc(["repro"], dst)
    assert "Running stage" not in out
    params = yaml.safe_load((dst / "params.yaml").read_text())
    params["track"]["gain"] = 0.8  # read by track_demos only: the re-executions, and what is trained on them, change
    (dst / "params.yaml").write_text(yaml.safe_dump(params, sort_keys=False))
    out = _dvc(["repro"], dst, timeout=smoke.REPRO_TIMEOUT_S)
    ran = {line.split("'")[1] for line in out.splitlines() if line.startswith("Running stage")}
    # the retrained policies become new versions of their registered models
    # preflight checks every params change first; its output is the same bytes, so it stales nothing itself
    assert ran == {"preflight", "track_demos@3", "bc_evaluate@lfdt_track-3", "report", "register_policies"}


def _runs_in(db: Path) -> list[dict]:
    import sqlite3

    with sqlite3.connect(db) as con:
        rows = con.execute("SELECT r.run_uuid, t.value FROM runs r LEFT JOIN tags t ON t.run_uuid = r.run_uuid "
                           "AND t.key = 'dvc.exp_name'").fetchall()
    return [{"run": r, "exp": e} for r, e in rows]


def test_temp_experiment_logs_to_the_workspace_store(project):
    """`dvc exp run --temp` runs in a copy under .dvc/tmp/exps that DVC deletes; its runs must land in the
    workspace's mlflow.db, not in the copy's."""
    dst, _ = project
    subprocess.run(["git", "add", "-A"], cwd=dst, check=True, capture_output=True)
    subprocess.run(["git", "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "smoke"], cwd=dst,
                   check=True, capture_output=True)
    before = _runs_in(dst / "mlflow.db")
    # twin.videos is read by the twin's evaluations only: three short stages rerun
    _dvc(["exp", "run", "--temp", "-n", "smoke-temp", "-S", "twin.videos=0"], dst, timeout=smoke.REPRO_TIMEOUT_S)
    after = _runs_in(dst / "mlflow.db")
    new = [r for r in after if r["run"] not in {b["run"] for b in before}]
    assert new, "the --temp experiment's runs are not in the workspace's mlflow.db"
    assert {r["exp"] for r in new} == {"smoke-temp"}
    assert not list((dst / ".dvc/tmp/exps").glob("**/mlflow.db"))


def test_mlflow_views_show_columns_the_runs_have(project, monkeypatch, capsys):
    """Each shared view of lfdt.mlflow_views finds runs of the pipeline, and every column it shows is a param or
    metric some of those runs log (a renamed metric would leave an empty column in the UI); Table I's runs log all of
    them."""
    import mlflow

    from lfdt import mlflow_views

    dst, _ = project
    uri = f"sqlite:///{dst / 'mlflow.db'}"
    monkeypatch.setenv("MLFLOW_TRACKING_URI", uri)
    exp_id, urls = mlflow_views.install()
    client = mlflow.MlflowClient(uri)
    tags = client.get_experiment(exp_id).tags
    assert len(urls) == len(mlflow_views.VIEWS)
    for frag, (view, state) in urls.items():
        assert frag == (f"#/experiments/{exp_id}/runs?viewStateShareKey={view.key}&workflowType=machine_learning")
        assert state == json.loads(tags[mlflow_views.SHARED_VIEW_TAG + view.key])
        if view.parent_stage:
            parent = mlflow_views.latest_run(client, exp_id, view.parent_stage)
            assert f"tags.`mlflow.parentRunId` = '{parent}'" in state["searchFilter"]
        runs = client.search_runs([exp_id], state["searchFilter"], max_results=500)
        assert runs, view.key
        for col in state["selectedColumns"]:
            kind, name = col.split(".", 1)
            name = name.strip("`")
            have = [name in (r.data.params if kind == "params" else r.data.metrics) for r in runs]
            assert all(have) if view.key == "lfdt-table1" else any(have), f"{view.key}: runs lack {col}"
    table1 = json.loads(tags[mlflow_views.SHARED_VIEW_TAG + "lfdt-table1"])
    # exactly the evaluation runs behind the newest Table I, not those of earlier runs of the pipeline
    shown = client.search_runs([exp_id], table1["searchFilter"], max_results=500)
    assert sorted(r.info.run_name for r in shown) == sorted(
        f"{m}-d3-s{s} evaluate" for m in METHODS for s in SEEDS)
    # each parent run keeps the list of the runs it was built from, also after a later one adopts them
    parent = mlflow_views.latest_run(client, exp_id, "report")
    kept = mlflow.artifacts.load_dict(f"runs:/{parent}/children.json")["runs"]
    assert len(kept) == json.loads((dst / "runs/table1.json").read_text())["mlflow_child_runs"]
    assert {r.info.run_id for r in shown} <= set(kept)
    # what `make mlflow-ui` prints: every view's URL on the given UI
    assert mlflow_views.main(["--ui", "http://ui.example:5000/"]) == 0
    printed = capsys.readouterr().out
    assert all(f"http://ui.example:5000/{frag}" in printed for frag in urls)
    pipelines = json.loads(tags[mlflow_views.SHARED_VIEW_TAG + "lfdt-pipelines"])
    assert {f"metrics.`{m}_d3_success_rate`" for m in METHODS} <= set(pipelines["selectedColumns"])
