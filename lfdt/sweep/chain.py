"""One chain of a sweep, run where Ray puts it: a fresh clone at the sweep's commit, `dvc repro` of the chain's
stages (its upstream restored from the run cache, never rebuilt), and its run records published to the remote."""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from lfdt.errors import StageError
from lfdt.sweep import runcache

RAN = re.compile(r"^Running stage '([^']+)'", re.M)
RESTORED = re.compile(r"^Stage '([^']+)' is cached - skipping run", re.M)
LOG_TAIL = 20_000


class RemoteError(StageError):
    """The sweep's DVC remote is not configured."""


@dataclass(frozen=True)
class Remote:
    """The DVC remote every machine of a sweep shares."""

    name: str
    """Its name in the project's DVC config ('sweep' when the sweep adds it from ``url``)."""
    url: str | None = None
    """Added to each clone's local config under ``name`` when given (else ``name`` must be in the commit's config)."""
    endpoint_url: str | None = None
    """An S3-compatible endpoint other than AWS's (MinIO, Ceph, a test server)."""

    def configure(self, root: Path) -> None:
        """Make this remote ``root``'s default in its local DVC config (`dvc repro --pull` pulls from the default),
        adding it there when it has a URL (else it must be a remote of the committed config). In-process: two
        `dvc remote` commands per clone cost seconds of imports."""
        from dvc.repo import Repo

        with contextlib.chdir(root), Repo(str(root)) as repo:
            if self.url is None and self.name not in repo.config["remote"]:
                raise RemoteError(f"DVC remote {self.name!r} is not in {root.resolve()}'s config: commit it to "
                                  f".dvc/config or give its URL (--remote-url)")
            with repo.config.edit("local") as conf:
                if self.url is not None:
                    conf["remote"][self.name] = {"url": self.url, **({"endpointurl": self.endpoint_url}
                                                                     if self.endpoint_url else {})}
                conf["core"]["remote"] = self.name


@dataclass(frozen=True)
class ChainSpec:
    """Everything a worker needs to run one chain."""

    name: str
    stages: tuple[str, ...]
    shared: tuple[str, ...]
    repo_url: str
    commit: str
    params_yaml: str
    remote: Remote
    env: dict[str, str] = field(default_factory=dict)
    """Variables set for the chain's stages (the tracking URI, the MLflow experiment, any the user forwards)."""
    workdir: str | None = None
    """Where the clone goes on the worker (default: its temporary directory)."""


@dataclass
class ChainResult:
    """What a chain reports back."""

    name: str
    ok: bool
    host: str
    wall_s: float
    ran: list[str]
    restored: list[str]
    error: str = ""
    log_tail: str = ""
    clone: str = ""
    """Where the chain ran on ``host`` (kept there when it failed)."""


class ChainFailed(RuntimeError):
    """A command of a chain exited non-zero; carries its output."""

    def __init__(self, message: str, output: str = ""):
        super().__init__(message)
        self.output = output


def safe_name(name: str) -> str:
    """A chain's name as a file name (stage names hold '@')."""
    return re.sub(r"[^A-Za-z0-9_.-]", "_", name)


def stage_env(root: Path, extra: dict[str, str]) -> dict[str, str]:
    """The environment of a DVC command in ``root``: this interpreter first on PATH (stages run ``python``), the
    clone's own code first on the import path, no DVC analytics, MuJoCo rendering off-screen."""
    env = {**os.environ, **extra}
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env["PYTHONPATH"] = str(root) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    env.setdefault("MUJOCO_GL", "egl")
    env["DVC_NO_ANALYTICS"] = "1"
    return env


def dvc(root: Path, env: dict[str, str], *args: str, log=None) -> str:
    """Run ``dvc args`` in ``root``; returns its output, ChainFailed with the output when it fails."""
    proc = subprocess.run([sys.executable, "-m", "dvc", *args], cwd=root, env=env, text=True,
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    if log is not None:
        log.write(f"$ dvc {' '.join(args)}\n{proc.stdout}\n")
        log.flush()
    if proc.returncode != 0:
        raise ChainFailed(f"`dvc {' '.join(args)}` exited with {proc.returncode}", proc.stdout)
    return proc.stdout


def git(args: list[str], cwd: Path | None = None) -> str:
    """Run git; ChainFailed with its output when it fails."""
    proc = subprocess.run(["git", *args], cwd=cwd, text=True, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    if proc.returncode != 0:
        raise ChainFailed(f"`git {' '.join(args)}` exited with {proc.returncode}", proc.stdout)
    return proc.stdout


def run_chain(spec: ChainSpec) -> ChainResult:
    """Clone, restore the shared stages, run the chain's stages, publish their run records. Never raises: a failure
    comes back as a result that names the command and carries the end of the log."""
    start = time.monotonic()
    base = Path(spec.workdir or tempfile.gettempdir())
    base.mkdir(parents=True, exist_ok=True)
    clone = Path(tempfile.mkdtemp(prefix=f"lfdt-chain-{safe_name(spec.name)}-", dir=base))
    log_path = clone.with_suffix(".log")
    result = ChainResult(spec.name, ok=False, host=socket.gethostname(), wall_s=0.0, ran=[], restored=[],
                         clone=str(clone))
    with open(log_path, "w") as log:
        try:
            git(["clone", "--quiet", "--no-checkout", "--", spec.repo_url, str(clone)])  # a URL is never an option
            git(["checkout", "--quiet", spec.commit], cwd=clone)
            (clone / "params.yaml").write_text(spec.params_yaml)
            env = stage_env(clone, spec.env)
            spec.remote.configure(clone)
            runcache.fetch(clone, spec.remote.name)
            out = dvc(clone, env, "repro", "--pull", *spec.stages, log=log)
            result.ran, result.restored = RAN.findall(out), RESTORED.findall(out)
            rebuilt = sorted(set(result.ran) & set(spec.shared))
            if rebuilt:
                raise ChainFailed(f"shared stages {rebuilt} were not in the remote's run cache and ran again in "
                                  f"this chain: the coordinator publishes them before the chains start", out)
            runcache.publish(clone, spec.remote.name)
            result.ok = True
        except ChainFailed as e:
            result.error = str(e)
            log.write(e.output)
        except Exception as e:  # noqa: BLE001 - reported back by name to the coordinator, which fails the sweep
            result.error = f"{type(e).__name__}: {e}"
    result.wall_s = time.monotonic() - start
    result.log_tail = log_path.read_text()[-LOG_TAIL:]
    if result.ok:
        shutil.rmtree(clone, ignore_errors=True)
        log_path.unlink(missing_ok=True)
    return result
