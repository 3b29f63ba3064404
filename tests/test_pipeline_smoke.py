"""The whole DVC DAG on tiny params: every stage runs, every artifact has its schema, reruns are incremental."""

import json
import os
import shutil
import subprocess
import sys
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


def test_every_stage_ran(project):
    _, out = project
    for stage in ("train_experts@R1H", "train_experts@HR2", "collect_random@Y", "collect_random@R1H",
                  "collect_random@HR2", "collect_demos@R1H", "collect_demos@HR2", "summarize_experts"):
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


def test_second_repro_does_nothing_and_param_change_reruns_only_dependents(project):
    dst, _ = project
    out = _dvc(["repro"], dst)
    assert "Running stage" not in out
    params = yaml.safe_load((dst / "params.yaml").read_text())
    params["demos"]["per_pairing"] = 2
    (dst / "params.yaml").write_text(yaml.safe_dump(params, sort_keys=False))
    out = _dvc(["repro"], dst)
    ran = sorted(line.split("'")[1] for line in out.splitlines() if line.startswith("Running stage"))
    assert ran == ["collect_demos@HR2", "collect_demos@R1H", "summarize_experts"]
