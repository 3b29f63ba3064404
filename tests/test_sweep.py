"""A sweep of the smoke params through a Ray cluster of two nodes, a DVC remote on an S3 server and an MLflow server
on PostgreSQL, all started here on 127.0.0.1 and stopped by process id: the coordinator trains nothing again, its
workspace is clean, the tracking server holds every run, and Table I is the plain `dvc repro`'s, byte for byte,
although one chain was killed half-way: it is reported by name, and the rerun runs only it."""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import mlflow
import pytest
import services
import smoke

from lfdt.sweep.chain import RAN, safe_name
from lfdt.sweep.plan import make_plan

BUCKET = "lfdt-sweep"


@dataclass
class Cluster:
    s3: str
    mlflow: str
    ray: str


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    logs = tmp_path_factory.mktemp("service-logs")
    with services.postgres(logs) as pg, services.s3_server(logs, BUCKET) as s3, \
            services.mlflow_server(logs, pg, f"s3://{BUCKET}/mlartifacts", s3) as ml, \
            services.ray_cluster(logs, workers=1, env=services.S3_ENV) as address:
        yield Cluster(s3, ml, address)


def _sweep(coord: Path, cluster: Cluster, *extra: str, background: bool = False):
    env = {**os.environ, **services.S3_ENV, "MLFLOW_TRACKING_URI": cluster.mlflow,
           "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}", "DVC_NO_ANALYTICS": "1"}
    args = [sys.executable, "-m", "lfdt.sweep", "--address", cluster.ray, "--remote-url", f"s3://{BUCKET}/dvc",
            "--endpoint-url", cluster.s3, "--workdir", str(coord.parent / "chains"), *extra]
    if background:
        return subprocess.Popen(args, cwd=coord, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                text=True, start_new_session=True)
    return subprocess.run(args, cwd=coord, env=env, capture_output=True, text=True, timeout=1200)


def _run_ids(root: Path) -> set[str]:
    ids = set()
    for f in (root / "reports").rglob("*.json"):
        obj = json.loads(f.read_text())
        seeds = obj.get("seeds") if isinstance(obj.get("seeds"), dict) else {}
        for rec in [obj, *seeds.values()]:
            if isinstance(rec, dict) and rec.get("mlflow_run_id"):
                ids.add(rec["mlflow_run_id"])
    return ids


def _pids_in(clone_prefix: str) -> list[int]:
    """Processes whose working directory is a chain clone whose name starts with ``clone_prefix``."""
    pids = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                if Path(os.readlink(d / "cwd")).name.startswith(clone_prefix):
                    pids.append(int(d.name))
            except OSError:
                continue
    return pids


def _kill_chain_when_a_stage_runs(proc: subprocess.Popen, chain: str, stage_script: str) -> bool:
    """Wait until a stage of ``chain`` runs on a worker, then kill every process of that chain."""
    prefix = f"lfdt-chain-{safe_name(chain)}-"
    deadline = time.monotonic() + 600
    while time.monotonic() < deadline and proc.poll() is None:
        for pid in _pids_in(prefix):
            try:
                cmd = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
            except OSError:
                continue
            if stage_script in cmd:
                for p in _pids_in(prefix):
                    with contextlib.suppress(ProcessLookupError):
                        os.kill(p, signal.SIGKILL)
                return True
        time.sleep(0.2)
    return False


def test_sweep_with_a_killed_chain_resumes_and_gives_the_plain_repro_tables(smoke_project, cluster, tmp_path):
    coord = smoke.make_project(tmp_path / "coordinator", commit=True)
    plan = make_plan(coord)
    assert len(plan.chains) >= 4 and plan.shared and "report" in plan.final
    chain_stages = {s for stages in plan.chains.values() for s in stages}
    victim = "twin_collect@peg_insertion"
    assert victim in plan.chains

    # first run: one chain is killed half-way; it is reported by name, the others finish
    proc = _sweep(coord, cluster, background=True)
    killed = _kill_chain_when_a_stage_runs(proc, victim, "stages/twin_")
    out, _ = proc.communicate(timeout=1200)
    assert killed, "the victim chain's stage was never seen running:\n" + out[-3000:]
    assert proc.returncode == 2, out[-3000:]
    assert f"FAILED: {victim}" in out and f"1 of {len(plan.chains)} chains failed" in out
    assert len(re.findall(r"^done: ", out, re.M)) == len(plan.chains) - 1
    ran_here = set(RAN.findall(out))
    assert set(plan.shared) <= ran_here and not ran_here & chain_stages  # shared once, here; chains elsewhere

    # the rerun runs only the killed chain, then restores every chain and builds the reports here
    rerun = _sweep(coord, cluster)
    assert rerun.returncode == 0, rerun.stdout[-4000:] + rerun.stderr[-4000:]
    assert re.findall(r"^done: (\S+)", rerun.stdout, re.M) == [victim]
    assert f"{len(plan.chains) - 1} chains finished in an earlier run of this sweep" in rerun.stdout
    ran_here = set(RAN.findall(rerun.stdout))
    assert not ran_here & chain_stages and not ran_here & set(plan.shared), sorted(ran_here)
    assert {"report", "twin_report"} <= ran_here

    assert "up to date" in smoke.dvc(["status"], coord)
    for table, plain in smoke_project.tables.items():
        assert (coord / table).read_bytes() == plain, f"{table} differs from the plain `dvc repro`"

    # the tracking server holds every run behind the reports, each adopted by the report's parent run
    client = mlflow.MlflowClient(cluster.mlflow)
    parent = json.loads((coord / "reports/report.json").read_text())["mlflow_parent_run_id"]
    ids = _run_ids(coord) - {parent}
    assert len(ids) >= len(plan.chains)
    for rid in ids:
        assert client.get_run(rid).info.status == "FINISHED"
    exp = client.get_experiment_by_name("lfdt")
    evaluate = client.search_runs([exp.experiment_id], "tags.`lfdt.stage` = 'evaluate'", max_results=500)
    assert {r.info.run_id for r in evaluate} <= ids
    assert len(evaluate) == sum(s.startswith("evaluate@") for s in chain_stages) * 2  # two seeds each
    children = client.search_runs([exp.experiment_id], f"tags.`mlflow.parentRunId` = '{parent}'", max_results=500)
    assert {r.info.run_id for r in evaluate} <= {r.info.run_id for r in children}
