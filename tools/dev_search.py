"""A budgeted search over the translator's knobs on the development block (issue 37, item 3), with Optuna.

Each trial is one development trial (``tools/dev_trial.py``: LfDT's translators, BC and its evaluation on the
development seeds and the development start states, logged to MLflow and appended to
``docs/experiments/trials.csv``) with the knobs Optuna proposes. What is searched and what is maximised are fixed
here, before a study runs (:data:`SPACE`, :data:`OBJECTIVE`); the first trial is the workspace's own params, so the
study has its baseline measured the same way. The study lives in ``dev/search/<study>.db`` (Optuna's SQLite storage):
a study that was stopped (Ctrl-C, a crash, the budget) goes on where it stopped when run again with the same name,
and each finished trial is a row of ``docs/experiments/search_<study>.csv`` as soon as it ends.

    python tools/dev_search.py --study i37-search-d50 --trials 12 --budget-min 70

The evaluation start states and seeds are never used (``tools/dev_trial.py`` refuses them).
"""

import lfdt.numerics  # noqa: F401

import argparse
import csv
import json
import re
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import optuna
import yaml

ROOT = Path(__file__).resolve().parents[1]
TRIALS = ROOT / "docs" / "experiments" / "trials.csv"

SPACE = {
    "translator.lambda_dyn": [3.0, 10.0, 30.0],
    "translator.lambda_id": [30.0, 100.0, 300.0],
    "translator.lambda_side": [0.0, 3.0, 10.0],
    "translator.batch_size": [64, 128, 256],
    "translator.learning_rate": [0.0001, 0.0003, 0.001],
}
"""The knobs searched and their values (each categorical: 243 combinations), around the adopted config."""

OBJECTIVE = "success_pct"
"""What a trial maximises: LfDT's mean success (end-state rule) over the development seeds and start states, the
column of docs/experiments/trials.csv; the worst seed and the path rule are recorded beside it, not optimised."""

MAX_REPEATS = 50
"""A study stops after the sampler proposed this many points already measured (a small space runs out)."""

RECORDED = ("success_pct", "worst_seed_pct", "per_seed_pct", "path_success_pct", "path_worst_seed_pct", "wall_min")
"""The columns of a trial's row of trials.csv copied into the study's table."""


def _current(key: str) -> object:
    doc = yaml.safe_load((ROOT / "params.yaml").read_text())
    for k in key.split("."):
        doc = doc[k]
    return doc


def _row(trial: str, demos: int) -> dict:
    with TRIALS.open(newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["trial"] == trial and r["method"] == "lfdt"
                and r["demos"] == str(demos)]
    if not rows:
        raise RuntimeError(f"{TRIALS} has no lfdt row of trial {trial!r} at {demos} demonstrations")
    return rows[-1]


def run_study(name: str, storage: str, run_trial: Callable[[int, dict, bool], dict], baseline: dict,
              trials: int, budget_min: float, sampler_seed: int, table: Path, attrs: dict) -> optuna.Study:
    """Run (or go on with) the study ``name`` in ``storage`` until it has ``trials`` finished trials or
    ``budget_min`` minutes have passed (checked before each trial). ``run_trial(number, values, is_baseline)``
    runs one trial and returns its row (:data:`OBJECTIVE` and :data:`RECORDED`); ``baseline`` is trial 0's values.
    A trial left running by a stopped run is marked failed; ``table`` is rewritten after every trial. A study goes on
    only with the settings (``attrs``: objective, space, seeds, demos) it started with; the baseline is queued again
    while it has not finished. A point the sampler proposes again is not run again (the trials are deterministic:
    the same params give the same bits): it is told the earlier trial's value and does not count as a trial."""
    sampler = optuna.samplers.TPESampler(seed=sampler_seed, n_startup_trials=5)
    study = optuna.create_study(study_name=name, storage=storage, direction="maximize", sampler=sampler,
                                load_if_exists=True)
    state = optuna.trial.TrialState
    for t in study.get_trials(deepcopy=False, states=(state.RUNNING,)):
        study.tell(t.number, state=state.FAIL)  # a trial the last run was stopped in
    if not study.trials:
        for k, v in attrs.items():
            study.set_user_attr(k, v)
    changed = {k: (study.user_attrs.get(k), v) for k, v in attrs.items() if study.user_attrs.get(k) != v}
    if changed:
        k, (old, new) = next(iter(changed.items()))
        raise SystemExit(f"dev_search: study {name!r} in {storage} ran with {k} = {old!r}, this run asks for {new!r}: "
                         f"a study's trials must be comparable (name a new study)")
    if not any(t.user_attrs.get("baseline") and t.state in (state.COMPLETE, state.WAITING) for t in study.trials):
        study.enqueue_trial(baseline, user_attrs={"baseline": True})
    t0 = time.monotonic()
    repeats = 0
    while True:
        done = [t for t in study.trials if t.state == state.COMPLETE and "repeat_of" not in t.user_attrs]
        if len(done) >= trials:
            break
        if repeats >= MAX_REPEATS:
            print(f"dev_search: the sampler proposed {repeats} points already measured; stopping", file=sys.stderr)
            break
        if (time.monotonic() - t0) / 60 > budget_min:
            print(f"dev_search: budget of {budget_min} min spent after {len(done)} trials", file=sys.stderr)
            break
        trial = study.ask()
        values = {k: trial.suggest_categorical(k, v) for k, v in SPACE.items()}
        same = next((t for t in done if t.params == values), None)
        if same is not None:  # the trials are deterministic: a point measured before is not run again
            repeats += 1
            trial.set_user_attr("repeat_of", same.number)
            for k in RECORDED:
                trial.set_user_attr(k, same.user_attrs.get(k, ""))
            study.tell(trial, same.value)
            continue
        try:
            row = run_trial(trial.number, values, bool(trial.user_attrs.get("baseline")))
            value = float(row[OBJECTIVE])
            for k in RECORDED:
                trial.set_user_attr(k, row[k])
        except BaseException:
            study.tell(trial, state=state.FAIL)
            raise
        study.tell(trial, value)
        _write_table(study, table)
    _write_table(study, table)
    return study


def main() -> None:
    """Run (or go on with) a study."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--study", required=True, help="the study's name (its trials are <study>-t<n>)")
    ap.add_argument("--demos", type=int, default=50, help="demonstrations per pairing (default 50)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[40, 41, 42, 43, 44],
                    help="development seeds (default 40-44)")
    ap.add_argument("--trials", type=int, default=12, help="trials of the study in all, the baseline included")
    ap.add_argument("--budget-min", type=float, default=70.0, help="start no trial after this many minutes")
    ap.add_argument("--sampler-seed", type=int, default=0, help="the TPE sampler's seed")
    args = ap.parse_args()
    if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.-]*", args.study):
        raise SystemExit(f"dev_search: --study {args.study!r}: letters, digits, '_', '.' and '-' only (it names files)")
    unknown = [k for k in SPACE if _current(k) not in SPACE[k]]
    if unknown:
        raise SystemExit(f"params.yaml's {unknown[0]} = {_current(unknown[0])!r} is not among the searched values "
                         f"{SPACE[unknown[0]]}: the baseline trial must be a point of the space")
    folder = ROOT / "dev" / "search"
    folder.mkdir(parents=True, exist_ok=True)
    db, table = folder / f"{args.study}.db", ROOT / "docs" / "experiments" / f"search_{args.study}.csv"
    with TRIALS.open(newline="") as f:
        earlier = [r["trial"] for r in csv.DictReader(f) if r["trial"].startswith(f"{args.study}-t")]
    if not db.exists() and (table.exists() or earlier):
        found = table.name if table.exists() else earlier[0]
        raise SystemExit(f"dev_search: study {args.study!r} has results in docs/experiments ({found}) but no {db}: "
                         f"its trials would be overwritten (name a new study)")

    def run_trial(number: int, values: dict, is_baseline: bool) -> dict:
        name = f"{args.study}-t{number}"
        changes = [f"{k}={v}" for k, v in values.items() if v != _current(k)]
        hypothesis = (f"search {args.study}, trial {number} "
                      f"({'baseline: params.yaml' if is_baseline else 'TPE proposal'}); "
                      f"objective fixed before the study: LfDT mean success (end state), {args.demos} demos, "
                      f"development seeds {' '.join(map(str, args.seeds))}")
        cmd = [sys.executable, str(ROOT / "tools/dev_trial.py"), "--name", name, "--demos", str(args.demos),
               "--methods", "lfdt", "--seeds", *map(str, args.seeds), "--hypothesis", hypothesis]
        for c in changes:
            cmd += ["-S", c]
        print(f"dev_search: trial {number}: {' '.join(changes) or 'params.yaml as it is'}", file=sys.stderr)
        proc = subprocess.run(cmd, cwd=ROOT)
        if proc.returncode != 0:
            raise SystemExit(f"dev_search: trial {number} ({name}) failed with exit code {proc.returncode}")
        try:
            return _row(name, args.demos)
        except RuntimeError as e:
            raise SystemExit(f"dev_search: {e}") from None

    study = run_study(args.study, f"sqlite:///{db.resolve()}", run_trial, {k: _current(k) for k in SPACE},
                      args.trials, args.budget_min, args.sampler_seed, table,
                      {"objective": OBJECTIVE, "space": json.dumps(SPACE), "seeds": args.seeds, "demos": args.demos})
    if not any(t.state == optuna.trial.TrialState.COMPLETE for t in study.trials):
        print(f"dev_search: study {args.study!r} has no finished trial", file=sys.stderr)
        return
    best = study.best_trial
    print(f"dev_search: best of {len(study.trials)} trials: t{best.number} {best.value:.1f} % "
          f"({json.dumps(best.params)})", file=sys.stderr)


def _write_table(study, path: Path) -> None:
    """Every finished trial of the study, one row each, written whole (a crash keeps the last table)."""
    rows = [t for t in study.trials if t.state == optuna.trial.TrialState.COMPLETE]
    fields = ["trial", "baseline", "repeat_of", *SPACE, *RECORDED]
    tmp = path.with_suffix(".csv.tmp")
    with tmp.open("w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(fields)
        for t in rows:
            w.writerow([t.number, bool(t.user_attrs.get("baseline")), t.user_attrs.get("repeat_of", ""),
                        *(t.params[k] for k in SPACE),
                        *(t.user_attrs.get(k, "") for k in RECORDED)])
    tmp.replace(path)


if __name__ == "__main__":
    main()
