"""The sweep's plan of the real dvc.yaml, and what it refuses before anything runs (no servers needed)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import networkx as nx
import pytest
import smoke

from lfdt.sweep import coordinator
from lfdt.sweep.plan import make_plan, upstream_graph

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def repo(tmp_path):
    shutil.copy(ROOT / "dvc.yaml", tmp_path / "dvc.yaml")
    shutil.copy(ROOT / "params.yaml", tmp_path / "params.yaml")
    subprocess.run(["git", "init", "-q"], cwd=tmp_path, check=True)
    smoke.dvc(["init", "-q"], tmp_path)
    subprocess.run(["git", "add", "-A"], cwd=tmp_path, check=True)
    subprocess.run(["git", "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "x"], cwd=tmp_path,
                   check=True)
    return tmp_path


def test_plan_splits_the_dag_into_shared_independent_chains_and_final(repo):
    plan = make_plan(repo)
    g = upstream_graph(repo)
    groups = [set(plan.shared), set(plan.final), *map(set, plan.chains.values())]
    assert sum(len(x) for x in groups) == len(g) and set().union(*groups) == set(g)  # each stage in one group
    owner = {s: name for name, stages in plan.chains.items() for s in stages}
    for name, stages in plan.chains.items():
        for s in stages:
            for up in nx.descendants(g, s):
                assert up in plan.shared or owner.get(up) == name, (s, up)  # a chain needs only itself and shared
        order = {s: i for i, s in enumerate(stages)}
        assert all(order[b] < order[a] for a, b in g.subgraph(stages).edges)  # upstream first
    assert {"train_experts", "fit_dynamics", "collect_demos@R1H", "collect_random@Y"} <= set(plan.shared)
    assert {"report", "twin_report", "summarize_experts"} == set(plan.final)
    # lfdt_track re-executes lfdt's translations: one chain; the twin of each task is one chain
    assert {"train_translator@lfdt-50", "track_demos@50", "evaluate@lfdt_track-50"} <= \
        set(plan.chains["train_translator@lfdt-50"])
    assert set(plan.chains["twin_collect@block_push"]) == {"twin_collect@block_push", "twin_train@block_push",
                                                           "twin_evaluate@block_push"}
    assert len(plan.chains) == 3 * 4 + 2  # 3 demo counts x (3 translators + BC without translation), 2 twin tasks


def test_list_prints_the_plan(repo):
    out = subprocess.run([sys.executable, "-m", "lfdt.sweep", "--list"], cwd=repo, capture_output=True, text=True,
                         check=True).stdout
    assert out.startswith("shared (built once, here): ") and "chain select_demos@100: " in out


def test_sweep_refuses_uncommitted_code_and_a_local_tracking_store(repo, monkeypatch):
    (repo / "params.yaml").write_text((repo / "params.yaml").read_text() + "\n")
    assert coordinator.check_workspace(repo)  # params.yaml may differ: it is sent to every chain
    (repo / "dvc.yaml").write_text((repo / "dvc.yaml").read_text() + "\n")
    with pytest.raises(coordinator.SweepError, match="uncommitted changes in dvc.yaml"):
        coordinator.check_workspace(repo)
    for uri in ("", f"sqlite:///{repo}/mlflow.db", "mlruns"):
        monkeypatch.setenv("MLFLOW_TRACKING_URI", uri)
        with pytest.raises(coordinator.SweepError, match="tracking server every node reaches"):
            coordinator.tracking_env([])
    monkeypatch.setenv("MLFLOW_TRACKING_URI", "http://127.0.0.1:5000")
    assert coordinator.tracking_env([]) == {"MLFLOW_TRACKING_URI": "http://127.0.0.1:5000"}
    with pytest.raises(coordinator.SweepError, match="NOT_SET_ANYWHERE"):
        coordinator.tracking_env(["NOT_SET_ANYWHERE"])
