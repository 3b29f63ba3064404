"""A sweep of the smoke params through a Ray cluster of two nodes, a DVC remote on an S3 server and an MLflow server
on PostgreSQL, all started here on 127.0.0.1 and stopped by process id: the coordinator trains nothing again, its
workspace is clean, the tracking server holds every run, and Table I is the plain `dvc repro`'s, byte for byte. A
chain killed half-way is reported by name, and the rerun runs only it."""

from __future__ import annotations

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
import yaml

from lfdt.sweep.chain import RAN
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


def test_sweep_through_ray_gives_the_plain_repro_tables(smoke_project, cluster, tmp_path):
    coord = smoke.make_project(tmp_path / "coordinator", commit=True)
    plan = make_plan(coord)
    assert len(plan.chains) >= 4 and plan.shared and "report" in plan.final

    proc = _sweep(coord, cluster)
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-4000:]
    out = proc.stdout
    # here: the shared stages, once, and the final ones; every chain stage ran on a Ray worker, none here
    chain_stages = {s for stages in plan.chains.values() for s in stages}
    ran_here = set(RAN.findall(out))
    assert not ran_here & chain_stages, sorted(ran_here & chain_stages)
    assert set(plan.shared) <= ran_here and "report" in ran_here and "twin_report" in ran_here
    assert len(re.findall(r"^done: ", out + proc.stderr, re.M)) == len(plan.chains)

    assert "up to date" in smoke.dvc(["status"], coord)
    for table, plain in smoke_project.tables.items():
        assert (coord / table).read_bytes() == plain, f"{table} differs from the plain `dvc repro`"

    # the tracking server holds every run behind the reports, each adopted by the report's parent run
    client = mlflow.MlflowClient(cluster.mlflow)
    report = json.loads((coord / "reports/report.json").read_text())
    parent = report["mlflow_parent_run_id"]
    ids = _run_ids(coord) - {parent}
    assert len(ids) >= len(plan.chains)
    for rid in ids:
        run = client.get_run(rid)
        assert run.info.status == "FINISHED"
    exp = client.get_experiment_by_name("lfdt")
    evaluate = client.search_runs([exp.experiment_id], "tags.`lfdt.stage` = 'evaluate'", max_results=500)
    assert {r.info.run_id for r in evaluate} <= ids
    assert len(evaluate) == sum(s.startswith("evaluate@") for s in chain_stages) * 2  # two seeds each
    children = client.search_runs([exp.experiment_id], f"tags.`mlflow.parentRunId` = '{parent}'", max_results=500)
    assert {r.info.run_id for r in evaluate} <= {r.info.run_id for r in children}


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


def test_a_killed_chain_is_reported_and_the_rerun_runs_only_it(cluster, tmp_path):
    coord = smoke.make_project(tmp_path / "coordinator", commit=True)
    params = yaml.safe_load((coord / "params.yaml").read_text())
    params["twin"]["trials"] = 3  # only the twin chains' last stage sees it; the rest comes from the run cache
    (coord / "params.yaml").write_text(yaml.safe_dump(params, sort_keys=False))
    plan = make_plan(coord)
    victim = "twin_collect@peg_insertion"
    assert victim in plan.chains

    proc = _sweep(coord, cluster, background=True)
    prefix = "lfdt-chain-" + victim.replace("@", "_")
    deadline = time.monotonic() + 600
    killed = False
    while time.monotonic() < deadline and proc.poll() is None and not killed:
        for pid in _pids_in(prefix):
            with open(f"/proc/{pid}/cmdline", "rb") as fh:
                cmd = fh.read().replace(b"\0", b" ").decode()
            if "stages/twin_" in cmd:  # a stage of the victim is running: kill the chain's processes
                for p in _pids_in(prefix):
                    os.kill(p, signal.SIGKILL)
                killed = True
                break
        time.sleep(0.2)
    out, _ = proc.communicate(timeout=900)
    assert killed, "the victim chain's stage was never seen running:\n" + out[-3000:]
    assert proc.returncode == 2, out[-3000:]
    assert f"FAILED: {victim}" in out and "1 of" in out and victim in out.splitlines()[-1]

    rerun = _sweep(coord, cluster)
    assert rerun.returncode == 0, rerun.stdout[-4000:] + rerun.stderr[-4000:]
    done = re.findall(r"^done: (\S+)", rerun.stdout + rerun.stderr, re.M)
    assert done == [victim]
    assert "finished in an earlier run of this sweep" in rerun.stdout
    assert "up to date" in smoke.dvc(["status"], coord)
