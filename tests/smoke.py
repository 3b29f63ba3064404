"""A copy of the project on the tiny smoke params (tests/smoke_params.yaml), for the tests that run the whole DAG."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import yaml

from lfdt.config import validate_params

ROOT = Path(__file__).resolve().parents[1]
PROJECT_FILES = ("dvc.yaml", "lfdt", "stages", "data/real")  # data/real: the twin stages' robot-data dependency
TABLES = ("reports/table1.csv", "reports/table1_runs.csv", "reports/twin_runs.csv")
"""What a run of the smoke params reports: a sweep of the same params must give them byte for byte."""
REPRO_TIMEOUT_S = 2400
"""How long a full `dvc repro` of the smoke params may take before the test calls it hung (as the sweep's 1200 s
per chain: a guard against a hang, well inside CI's 90 minutes, never a speed test)."""


def dvc(args: list[str], cwd: Path, timeout: float = 600) -> str:
    """Run dvc in ``cwd`` with this interpreter's tools first on PATH and the project's own tracking store (any
    MLFLOW_TRACKING_URI of the caller's removed); fail the test with its output otherwise."""
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}", "DVC_NO_ANALYTICS": "1"}
    env.pop("MLFLOW_TRACKING_URI", None)
    proc = subprocess.run([sys.executable, "-m", "dvc", *args], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=timeout)
    assert proc.returncode == 0, f"dvc {' '.join(args)} failed:\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    return proc.stdout + proc.stderr


def merge(base: dict, over: dict) -> dict:
    """params.yaml with the smoke values laid over it, section by section, at any depth."""
    out = dict(base)
    for k, v in over.items():
        out[k] = merge(base[k], v) if isinstance(v, dict) and isinstance(base.get(k), dict) else v
    return out


def smoke_params_yaml() -> str:
    """params.yaml's text for the smoke run."""
    params = merge(yaml.safe_load((ROOT / "params.yaml").read_text()),
                   yaml.safe_load((ROOT / "tests/smoke_params.yaml").read_text()))
    validate_params(params)
    return yaml.safe_dump(params, sort_keys=False)


def make_project(dst: Path, commit: bool = False) -> Path:
    """The project's code, dvc.yaml and the smoke params in ``dst``, a git and DVC repository (committed when
    ``commit``: a sweep's chains clone a commit)."""
    dst.mkdir(parents=True, exist_ok=True)
    for name in PROJECT_FILES:
        src = ROOT / name
        if src.is_dir():
            shutil.copytree(src, dst / name, ignore=shutil.ignore_patterns("__pycache__"))
        else:
            shutil.copy(src, dst / name)
    (dst / "params.yaml").write_text(smoke_params_yaml())
    subprocess.run(["git", "init", "-q"], cwd=dst, check=True)
    dvc(["init", "-q"], dst)
    dvc(["config", "core.analytics", "false"], dst)
    if commit:
        subprocess.run(["git", "add", "-A"], cwd=dst, check=True)
        subprocess.run(["git", "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "smoke"], cwd=dst,
                       check=True)
    return dst
