"""tools/dev_search.py's study loop, with a stand-in for the development trial: the baseline first, the table after
every trial, and a stopped study going on where it stopped."""

import csv
import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def dev_search():
    spec = importlib.util.spec_from_file_location("dev_search", ROOT / "tools" / "dev_search.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    return module


BASELINE = {"translator.lambda_dyn": 10.0, "translator.lambda_id": 100.0, "translator.lambda_side": 0.0,
            "translator.batch_size": 128, "translator.learning_rate": 0.0003}


def _fake(calls: list, stop_at: int | None = None):
    def run_trial(number: int, values: dict, is_baseline: bool) -> dict:
        calls.append((number, values, is_baseline))
        if number == stop_at:
            raise KeyboardInterrupt
        score = 50 + 2 * values["translator.lambda_side"] - values["translator.lambda_dyn"] / 10
        return {"success_pct": f"{score:.1f}", "worst_seed_pct": "1.0", "per_seed_pct": "1 2", "path_success_pct": "2",
                "path_worst_seed_pct": "0.5", "wall_min": "0.1"}
    return run_trial


def _run(ds, tmp_path: Path, run_trial, trials: int = 4, budget_min: float = 60.0):
    return ds.run_study("s", f"sqlite:///{tmp_path / 's.db'}", run_trial, BASELINE, trials, budget_min, 0,
                        tmp_path / "search_s.csv", {"objective": ds.OBJECTIVE})


def _table(tmp_path: Path) -> list[dict]:
    return list(csv.DictReader((tmp_path / "search_s.csv").open()))


def test_the_baseline_runs_first_and_every_trial_is_a_row(dev_search, tmp_path):
    calls = []
    study = _run(dev_search, tmp_path, _fake(calls))
    assert calls[0] == (0, BASELINE, True) and not any(b for _, _, b in calls[1:])
    assert all(set(v) == set(dev_search.SPACE) and all(v[k] in dev_search.SPACE[k] for k in v) for _, v, _ in calls)
    rows = _table(tmp_path)
    assert [r["trial"] for r in rows] == ["0", "1", "2", "3"] and len(study.trials) == 4
    assert float(rows[0]["success_pct"]) == 49.0 and rows[0]["translator.lambda_dyn"] == "10.0"
    assert study.best_value == max(float(r["success_pct"]) for r in rows)


def test_a_stopped_study_goes_on_where_it_stopped(dev_search, tmp_path):
    """Ctrl-C inside trial 2: trials 0 and 1 stay in the table, trial 2 is marked failed; the rerun asks no
    baseline again, runs new trials until four are finished (a point measured before is not run again), and a
    trial that a killed run left running (no chance to mark it) is marked failed too."""
    import optuna

    calls = []
    with pytest.raises(KeyboardInterrupt):
        _run(dev_search, tmp_path, _fake(calls, stop_at=2))
    assert [r["trial"] for r in _table(tmp_path)] == ["0", "1"]
    study = optuna.load_study(study_name="s", storage=f"sqlite:///{tmp_path / 's.db'}")
    assert study.trials[2].state == optuna.trial.TrialState.FAIL
    study.ask()  # as a SIGKILL leaves it: running, never told
    again = []
    study = _run(dev_search, tmp_path, _fake(again))
    states = [t.state for t in study.trials]
    assert optuna.trial.TrialState.RUNNING not in states
    run = [t.number for t in study.trials
           if t.state == optuna.trial.TrialState.COMPLETE and "repeat_of" not in t.user_attrs]
    assert len(run) == 4 and states.count(optuna.trial.TrialState.FAIL) == 2
    assert [n for n, _, _ in again] == run[2:] and run[2] >= 4 and not any(b for _, _, b in again)
    assert [r["trial"] for r in _table(tmp_path) if not r["repeat_of"]] == [str(n) for n in run]


def test_no_trial_starts_once_the_budget_is_spent(dev_search, tmp_path, capsys):
    calls = []
    _run(dev_search, tmp_path, _fake(calls), budget_min=-1.0)
    assert not calls and "budget of -1.0 min spent after 0 trials" in capsys.readouterr().err


def test_a_failed_baseline_is_run_again_and_the_settings_cannot_change(dev_search, tmp_path):
    """Ctrl-C in trial 0: the rerun measures the baseline again (trial 1 here), and the table says which row it
    is; going on with other settings (here another objective) is refused by name, before any trial."""
    calls = []
    with pytest.raises(KeyboardInterrupt):
        _run(dev_search, tmp_path, _fake(calls, stop_at=0))
    again = []
    _run(dev_search, tmp_path, _fake(again), trials=2)
    assert again[0] == (1, BASELINE, True) and not again[1][2]
    rows = _table(tmp_path)
    assert [(r["trial"], r["baseline"]) for r in rows] == [("1", "True"), ("2", "False")]
    more = []
    with pytest.raises(SystemExit, match="ran with objective = 'success_pct', this run asks for 'path'"):
        dev_search.run_study("s", f"sqlite:///{tmp_path / 's.db'}", _fake(more), BASELINE, 4, 60.0, 0,
                             tmp_path / "search_s.csv", {"objective": "path"})
    assert not more


def test_a_point_proposed_again_is_not_run_again(dev_search, tmp_path, monkeypatch, capsys):
    """A space of two points: each runs once; the sampler's repeats are told the earlier value without running, do
    not count as trials, and the study stops once the sampler keeps proposing what it measured."""
    monkeypatch.setattr(dev_search, "SPACE", {"translator.lambda_side": [0.0, 10.0]})
    calls = []

    def run_trial(number, values, is_baseline):
        return _fake(calls)(number, {**BASELINE, **values}, is_baseline)

    study = dev_search.run_study("s", f"sqlite:///{tmp_path / 's.db'}", run_trial,
                                 {"translator.lambda_side": 0.0}, 5, 60.0, 0, tmp_path / "search_s.csv", {})
    assert sorted(v["translator.lambda_side"] for _, v, _ in calls) == [0.0, 10.0]
    assert "proposed 50 points already measured" in capsys.readouterr().err
    repeats = [t for t in study.trials if "repeat_of" in t.user_attrs]
    assert len(repeats) == dev_search.MAX_REPEATS
    assert all(t.value == study.trials[t.user_attrs["repeat_of"]].value for t in repeats)
    rows = _table(tmp_path)
    assert sum(1 for r in rows if not r["repeat_of"]) == 2
