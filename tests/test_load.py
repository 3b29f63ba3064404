"""The load test (tools/load_test.py) on a small budget: four sweeps' stage processes and the MLflow UI at once on
one sqlite store, two sweeps writing it directly and two through the MLflow server, lose no run, param or metric
row, and the UI answers every request; the count it makes finds a row that is missing."""

import sqlite3
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))

import load_test  # noqa: E402

SIZE = {"sweeps": 4, "points": 1, "workers": 2, "metrics": 4, "steps": 50}


@pytest.fixture(scope="module")
def loaded(tmp_path_factory):
    """(its folder, the report) of a small load test, both ways of reaching the store at once."""
    work = tmp_path_factory.mktemp("load")
    return work, load_test.load_test(**SIZE, timeout=400, workdir=work, store="mixed")


def test_four_sweeps_and_the_ui_lose_nothing(loaded):
    _, report = loaded
    assert report["problems"] == []
    assert report["runs_found"] == report["runs_logged"] == 4 * (1 + 2)
    assert report["metric_rows_found"] == report["metric_rows_logged"] == 4 * 2 * 4 * 50
    assert report["ui_requests"] > 0
    assert report["ui_errors"] == 0, report["ui_error_examples"]


def test_the_count_finds_a_lost_row_an_unfinished_run_and_a_stray_one(loaded):
    work, _ = loaded
    db = work / "mlflow.db"
    with sqlite3.connect(db) as con:
        run = con.execute("SELECT run_uuid FROM runs WHERE name = ?",
                          (load_test.CHILD.format(sweep=2, point=0, worker=1),)).fetchone()[0]
        con.execute("DELETE FROM metrics WHERE rowid IN (SELECT rowid FROM metrics WHERE run_uuid = ? LIMIT 1)",
                    (run,))
        con.execute("UPDATE runs SET status = 'RUNNING' WHERE name = ?",
                    (load_test.CHILD.format(sweep=0, point=0, worker=0),))
        con.execute("UPDATE runs SET name = 'stray' WHERE name = ?", (load_test.PARENT.format(sweep=3),))
    problems = load_test.count(db, **SIZE)["problems"]
    assert any(p.startswith("stray: 1 runs nobody logged") for p in problems), problems
    assert any(p.startswith(load_test.PARENT.format(sweep=3) + ": runs []") for p in problems), problems
    problems = [p for p in problems if "sweep 3" not in p and not p.startswith("stray")]
    assert len(problems) == 2, problems
    assert "sweep 2 point 0 worker 1: 199 metric rows" in problems[0] + problems[1]
    assert any("sweep 0 point 0 worker 0: runs" in p and "RUNNING" in p for p in problems)
