"""The sweep's plan of the real dvc.yaml, and what it refuses before anything runs (no servers needed)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import networkx as nx
import pytest
import smoke
import yaml

from lfdt.sweep import coordinator, points
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
    assert {"train_experts", "fit_dynamics", "collect_demos", "collect_random"} <= set(plan.shared)
    # fingerprint: no upstream, nothing downstream; register_policies: the policies of every chain
    assert {"report", "twin_report", "fingerprint", "register_policies"} == set(plan.final)
    # lfdt_track re-executes lfdt's translations: one chain; the twin of each task is one chain
    assert {"train_translator@lfdt-50", "track_demos@50", "bc_evaluate@lfdt_track-50"} <= \
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


def test_set_expands_every_combination_into_valid_params_with_comments_kept():
    base = (ROOT / "params.yaml").read_text()
    pts = points.expand(base, ["grid.seeds=[3,4,5],[3,4,5,6,7,8]", "translator.lambda_dyn=10,1"])
    assert [p.overrides for p in pts] == [
        (("grid.seeds", [3, 4, 5]), ("translator.lambda_dyn", 10)),
        (("grid.seeds", [3, 4, 5]), ("translator.lambda_dyn", 1)),
        (("grid.seeds", [3, 4, 5, 6, 7, 8]), ("translator.lambda_dyn", 10)),
        (("grid.seeds", [3, 4, 5, 6, 7, 8]), ("translator.lambda_dyn", 1))]
    assert len({p.name for p in pts}) == 4 and pts[2].name.startswith("seeds-3.4.5.6.7.8-lambda_dyn-10-")
    six = yaml.safe_load(pts[3].params_yaml)
    assert six["grid"]["seeds"] == [3, 4, 5, 6, 7, 8] and six["translator"]["lambda_dyn"] == 1
    changed = [(a, b) for a, b in zip(base.splitlines(), pts[3].params_yaml.splitlines(), strict=True) if a != b]
    assert len(changed) == 2 and all("# " in b for _, b in changed)  # only those two lines, comments kept
    assert pts[3].set_args() == ["-S", "grid.seeds=[3, 4, 5, 6, 7, 8]", "-S", "translator.lambda_dyn=1"]
    own = ",".join(str(s) for s in yaml.safe_load(base)["grid"]["seeds"])
    assert points.expand(base, [f"grid.seeds=[{own}]"])[0].params_yaml == base  # the workspace's own values
    # a key with one value is common to every point: names show only the keys that tell the points apart
    two = points.expand(base, ["grid.demos=[100]", "grid.seeds=[3,4,5],[3,4,5,6]"])
    assert [p.name.rsplit("-", 1)[0] for p in two] == ["seeds-3.4.5", "seeds-3.4.5.6"]


@pytest.mark.parametrize(("sets", "match"), [
    (["grid.seeds"], "expected KEY=VALUE"),
    (["translator.lambda_dyn=1,,2"], "an empty value"),
    (["translator.lambda_dyn=1", "translator.lambda_dyn=2"], "twice"),
    (["translator.lambda_dnn=1"], "no 'translator.lambda_dnn'"),
    (["translator.lambda_dyn=-1"], "translator.lambda_dyn = -1"),
    (["grid.seeds=[1,2],[1, 2]"], "same value twice"),
])
def test_set_refuses_what_would_not_run(sets, match):
    with pytest.raises(points.PointError, match=match):
        points.expand((ROOT / "params.yaml").read_text(), sets)


def test_split_values_keeps_brackets_and_quotes_whole():
    assert points.split_values("[3,4],[5], 'a,b' ,{x: 1, y: 2}") == ["[3,4]", "[5]", "'a,b'", "{x: 1, y: 2}"]


def test_compare_puts_the_points_tables_side_by_side():
    head = "method,demos,seeds,success_rate,ci95_low,ci95_high\n"
    three = head + "lfdt,100,3,0.49,0.14,0.84\nbc_no_translation,100,3,0.80,0.70,0.90\n"
    six = head + "lfdt,100,6,0.52,0.31,0.73\nlfdt,200,6,0.30,0.10,0.50\n"
    lines = points.compare({"seeds-3": three, "seeds-6": six}).splitlines()
    assert lines[0] == "| method | demos | seeds-3 | seeds-6 |"
    assert "| lfdt | 100 | 49.0% [14%, 84%], 3 seeds | 52.0% [31%, 73%], 6 seeds |" in lines
    assert "| bc_no_translation | 100 | 80.0% [70%, 90%], 3 seeds | - |" in lines
    assert "| lfdt | 200 | - | 30.0% [10%, 50%], 6 seeds |" in lines
