"""The whole DVC DAG on tiny params: every stage runs, every artifact has its schema, reruns are incremental."""

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest
import yaml

from lfdt import data, layout
from lfdt.config import validate_params

ROOT = Path(__file__).resolve().parents[1]


def _dvc(args, cwd, timeout=600):
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}", "DVC_NO_ANALYTICS": "1"}
    env.pop("MLFLOW_TRACKING_URI", None)
    proc = subprocess.run([sys.executable, "-m", "dvc", *args], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=timeout)
    assert proc.returncode == 0, f"dvc {' '.join(args)} failed:\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    return proc.stdout + proc.stderr


@pytest.fixture(scope="module")
def project(tmp_path_factory):
    """A copy of the project with the smoke params, after one full `dvc repro`."""
    dst = tmp_path_factory.mktemp("smoke")
    for name in ("dvc.yaml", "lfdt", "stages"):
        src = ROOT / name
        (shutil.copytree if src.is_dir() else shutil.copy)(src, dst / name)
    params = yaml.safe_load((ROOT / "params.yaml").read_text())
    for section, values in yaml.safe_load((ROOT / "tests/smoke_params.yaml").read_text()).items():
        params[section].update(values)
    validate_params(params)
    (dst / "params.yaml").write_text(yaml.safe_dump(params, sort_keys=False))
    subprocess.run(["git", "init", "-q"], cwd=dst, check=True)
    _dvc(["init", "-q"], dst)
    _dvc(["config", "core.analytics", "false"], dst)
    out = _dvc(["repro"], dst)
    return dst, out


METHODS = ("bc_no_translation", "lfdt", "lfdt_no_dyn", "lfdt_no_id")


def test_every_stage_ran(project):
    _, out = project
    stages = ["train_experts@R1H", "train_experts@HR2", "collect_random@Y", "collect_random@R1H",
              "collect_random@HR2", "collect_demos@R1H", "collect_demos@HR2", "summarize_experts", "fit_dynamics",
              "select_demos@3-0", "report", "twin_report"]
    stages += [f"{s}@{t}" for s in ("twin_collect", "twin_train", "twin_evaluate")
               for t in ("block_push", "peg_insertion")]
    stages += [f"train_translator@{m}-3-0" for m in METHODS[1:]]
    stages += [f"{s}@{m}-3-0" for s in ("train_bc", "evaluate") for m in METHODS]
    for stage in stages:
        assert f"'{stage}'" in out


def test_artifact_schemas(project):
    dst, _ = project
    for domain in layout.DOMAINS:
        meta = data.check_transitions(dst / f"data/random/{domain}.parquet", "random", domain)
        assert data.read_transitions(dst / f"data/random/{domain}.parquet").shape[0] == 3000
        assert meta["random"]["transitions"] == 3000
    for pairing in layout.PAIRINGS:
        data.check_transitions(dst / f"data/demos/{pairing}.parquet", "demos", pairing)
        df = data.read_transitions(dst / f"data/demos/{pairing}.parquet")
        assert df.episode_index.nunique() == 4
        cfg = json.loads((dst / f"models/experts/{pairing}/config.json").read_text())
        assert cfg["experts"]["total_timesteps"] == 800
        assert (dst / f"models/experts/{pairing}/policy.pt").exists()


def test_metrics_files(project):
    dst, _ = project
    summary = json.loads((dst / "reports/experts.json").read_text())
    assert set(summary) == set(layout.PAIRINGS)
    for entry in summary.values():
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
    for m in METHODS[1:]:
        name = f"{m}-d3-s0"
        path = dst / f"data/bc_train/{name}/translated.parquet"
        meta = data.read_metadata(path)
        assert meta["kind"] == "translated" and meta["method"] == m and meta["demos"] == 3
        df = data.read_transitions(path)
        assert df.episode_index.nunique() == 6 and set(df.source_pairing) == set(layout.PAIRINGS)
        want = [layout.STATE_PREFIX + c for c in layout.state_columns("Y")]
        want += [layout.ACTION_PREFIX + c for c in layout.action_columns("Y")]
        assert set(want) <= set(df.columns) and df[want].notna().all().all()
        tr = json.loads((dst / f"reports/translator/{name}.json").read_text())
        assert tr["replay_box_position_error_m"] >= 0 and 0 <= tr["final/D/accuracy"] <= 1
    for m in METHODS:
        name = f"{m}-d3-s0"
        ev = json.loads((dst / f"reports/eval/{name}.json").read_text())
        assert ev["trials"] == 2 and len(ev["per_trial"]) == 2
        assert (dst / f"reports/videos/{name}/trial00.mp4").stat().st_size > 1000
        assert list((dst / f"models/bc/{name}").glob("*.pt"))
    assert len(list((dst / "models/bc/bc_no_translation-d3-s0").glob("*.pt"))) == 2
    runs = (dst / "reports/table1_runs.csv").read_text().splitlines()
    assert runs[0].startswith("method,demos,seed,successes,trials") and len(runs) == 1 + len(METHODS)
    table = (dst / "reports/table1.csv").read_text().splitlines()
    assert len(table) == 1 + len(METHODS)
    md = (dst / "reports/table1.md").read_text()
    assert "LfDT" in md and "paper" in md and "80.0 %" not in md.split("|")[2]
    assert (dst / "reports/table1.tex").read_text().startswith("\\begin{tabular}")
    assert (dst / "reports/success_vs_demos.png").stat().st_size > 5000
    rep = json.loads((dst / "reports/report.json").read_text())
    assert rep["mlflow_child_runs"] == 2 + 3 + 2 + 1 + 3 + 4 + 4  # every run behind the table


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _post(url: str, body: dict) -> dict:
    req = urllib.request.Request(url, data=json.dumps(body).encode(), headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(req, timeout=10) as r:
        return json.loads(r.read())


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
        runs = _post(f"{base}/runs/search", {"experiment_ids": ids, "max_results": 500})["runs"]
        by_stage = {}
        for r in runs:
            tags = {t["key"]: t["value"] for t in r["data"].get("tags", [])}
            by_stage.setdefault(tags.get("lfdt.stage"), []).append(r)
        assert {"train_experts", "collect_random", "collect_demos", "fit_dynamics", "train_translator", "train_bc",
                "evaluate", "report"} <= set(by_stage)
        ev = by_stage["evaluate"]
        assert len(ev) == 4
        for r in ev:  # same param and metric names across methods, so the UI can compare them
            params = {p["key"] for p in r["data"]["params"]}
            metrics = {m["key"] for m in r["data"]["metrics"]}
            assert {"method", "demos", "seed", "evaluation.trials"} <= params
            assert {"success_rate", "successes", "trials"} <= metrics
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
    assert runs[0] == "task,method,trial,success"
    rows = [r.split(",") for r in runs[1:]]
    assert {(r[0], r[1]) for r in rows} == {(t, m) for t in ("block_push", "peg_insertion")
                                            for m in ("bc_no_translation", "lfdt")}
    assert len(rows) == 2 * 2 * 2 and {r[3] for r in rows} <= {"True", "False"}
    md = (dst / "reports/twin.md").read_text()
    assert "paper (real robots)" in md and "10/10" in md and "8/10" in md
    for task in ("block_push", "peg_insertion"):
        files = sorted((dst / f"data/twin/{task}/demos_R1H").glob("episode_*.parquet"))
        assert len(files) == 2
        assert (dst / f"models/twin/{task}/lfdt").is_dir() and (dst / f"models/twin/{task}/translator.pt").exists()


def test_second_repro_does_nothing_and_param_change_reruns_only_dependents(project):
    dst, _ = project
    out = _dvc(["repro"], dst)
    assert "Running stage" not in out
    params = yaml.safe_load((dst / "params.yaml").read_text())
    params["demos"]["per_pairing"] = 5
    (dst / "params.yaml").write_text(yaml.safe_dump(params, sort_keys=False))
    out = _dvc(["repro"], dst)
    ran = {line.split("'")[1] for line in out.splitlines() if line.startswith("Running stage")}
    downstream = {"collect_demos@HR2", "collect_demos@R1H", "summarize_experts", "select_demos@3-0", "report"}
    downstream |= {f"train_translator@{m}-3-0" for m in METHODS[1:]}
    downstream |= {f"{s}@{m}-3-0" for s in ("train_bc", "evaluate") for m in METHODS}
    assert ran == downstream  # experts, random motion and dynamics are not rerun
