"""A copy of the project on the tiny smoke params (tests/smoke_params.yaml), for the tests that run the whole DAG."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import yaml

from lfdt.config import validate_params

ROOT = Path(__file__).resolve().parents[1]
PROJECT_FILES = ("dvc.yaml", "lfdt", "stages", "data/real", "Makefile", "requirements.txt", "pyproject.toml")
"""What the smoke project copies: data/real is the twin stages' robot-data dependency; the Makefile (and what its
set-up rule reads) runs the README's quick start."""
QUICK_START = "## Set-up and the two commands"
"""The README section whose first shell block is the quick start the smoke project runs word for word."""
TABLES = ("reports/table1.csv", "reports/table1_runs.csv", "reports/twin_runs.csv")
"""What a run of the smoke params reports: a sweep of the same params must give them byte for byte."""
REPRO_TIMEOUT_S = 2400
"""How long a full `dvc repro` of the smoke params may take before the test calls it hung (as the sweep's 1200 s
per chain: a guard against a hang, well inside CI's 90 minutes, never a speed test)."""


def dvc(args: list[str], cwd: Path, timeout: float = 600, fails: bool = False,
        tracking_uri: str | None = None) -> str:
    """Run dvc in ``cwd`` with this interpreter's tools first on PATH and the project's own tracking store (any
    MLFLOW_TRACKING_URI of the caller's removed; ``tracking_uri`` sets one); fail the test with its output unless
    dvc succeeded (or, with ``fails``, unless it failed)."""
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}", "DVC_NO_ANALYTICS": "1"}
    env.pop("MLFLOW_TRACKING_URI", None)
    if tracking_uri is not None:
        env["MLFLOW_TRACKING_URI"] = tracking_uri
    proc = subprocess.run([sys.executable, "-m", "dvc", *args], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=timeout)
    assert (proc.returncode != 0) == fails, (f"dvc {' '.join(args)} {'succeeded' if fails else 'failed'}:\n"
                                             f"{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}")
    return proc.stdout + proc.stderr


def quick_start() -> list[str]:
    """The commands of the README's quick start (its section's first ```bash block), comments stripped."""
    text = (ROOT / "README.md").read_text()
    if QUICK_START not in text:
        raise AssertionError(f"README.md has no section {QUICK_START!r}: update tests/smoke.py's QUICK_START")
    block = re.search(r"```bash\n(.*?)```", text[text.index(QUICK_START):], re.S)
    assert block, f"README.md's {QUICK_START!r} has no ```bash block"
    return [c for line in block.group(1).splitlines() if (c := line.split("#", 1)[0].strip())]


def run_quick_start(cwd: Path, timeout: float = REPRO_TIMEOUT_S) -> str:
    """Run the README's quick start in the project ``cwd`` (the smoke params), with this interpreter's environment as
    its .venv; returns what it printed. ``make test`` is left out: it is the suite running this. ``make`` is told
    not to remake .venv's install stamp (``-o``): the set-up would otherwise reinstall this package from the copy."""
    commands = quick_start()
    assert "make reproduce" in commands, f"the README's quick start {commands} no longer runs `make reproduce`"
    venv = cwd / ".venv"
    if not venv.exists():
        venv.symlink_to(Path(sys.executable).parents[1])
        with (cwd / ".gitignore").open("a") as fh:
            fh.write("/.venv\n")
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}", "DVC_NO_ANALYTICS": "1"}
    env.pop("MLFLOW_TRACKING_URI", None)
    out = []
    for command in commands:
        if command == "make test":
            continue
        if command.startswith("make "):
            command = "make -o .venv/.installed " + command[len("make "):]
        proc = subprocess.run(["bash", "-c", command], cwd=cwd, env=env, capture_output=True, text=True,
                              timeout=timeout)
        assert proc.returncode == 0, f"README quick start `{command}` failed:\n{proc.stdout[-3000:]}\n" \
                                     f"{proc.stderr[-3000:]}"
        out.append(proc.stdout + proc.stderr)
    return "\n".join(out)


def merge(base: dict, over: dict) -> dict:
    """params.yaml with the smoke values laid over it, section by section, at any depth."""
    out = dict(base)
    for k, v in over.items():
        out[k] = merge(base[k], v) if isinstance(v, dict) and isinstance(base.get(k), dict) else v
    return out


def smoke_params_yaml(overrides: dict | None = None) -> str:
    """params.yaml's text for the smoke run (``overrides`` laid over the smoke params, section by section)."""
    params = merge(yaml.safe_load((ROOT / "params.yaml").read_text()),
                   yaml.safe_load((ROOT / "tests/smoke_params.yaml").read_text()))
    params = merge(params, overrides or {})
    validate_params(params)
    return yaml.safe_dump(params, sort_keys=False)


def make_project(dst: Path, commit: bool = False, overrides: dict | None = None) -> Path:
    """The project's code, dvc.yaml and the smoke params (with ``overrides``) in ``dst``, a git and DVC repository
    (committed when ``commit``: a sweep's chains clone a commit)."""
    dst.mkdir(parents=True, exist_ok=True)
    for name in PROJECT_FILES:
        src = ROOT / name
        if src.is_dir():
            shutil.copytree(src, dst / name, ignore=shutil.ignore_patterns("__pycache__"))
        else:
            shutil.copy2(src, dst / name)
    (dst / "params.yaml").write_text(smoke_params_yaml(overrides))
    subprocess.run(["git", "init", "-q"], cwd=dst, check=True)
    dvc(["init", "-q"], dst)
    dvc(["config", "core.analytics", "false"], dst)
    shutil.copy2(ROOT / ".dvcignore", dst / ".dvcignore")  # after `dvc init`, which writes its own
    if commit:
        subprocess.run(["git", "add", "-A"], cwd=dst, check=True)
        subprocess.run(["git", "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "smoke"], cwd=dst,
                       check=True)
    return dst
