"""One development trial: the matrix jobs of some methods and demo counts on development seeds and the development
start states, with params changed as ``dvc exp run -S`` would, outside the DVC pipeline.

For choosing settings without touching the evaluation start states (or the evaluation seeds): it runs the same jobs
as the translator, select, track, BC and evaluation stages (``lfdt/box_push_jobs``), on the workspace's demonstrations,
random motion and dynamics, writing into ``dev/<name>/`` (git-ignored), logging every job to MLflow (tagged with the
trial's name), and appends one row per (method, demos) to ``docs/experiments/trials.csv``: the per-seed success
rates, their mean and 95 % interval over seeds and start states, and the paired difference from BC without
translation where it ran. Per-seed diagnostics (translator and BC) go to ``docs/experiments/<name>_seeds.csv``.

    python tools/dev_trial.py --name baseline --demos 100 --methods lfdt bc_no_translation
    python tools/dev_trial.py --name lr-decay --demos 100 --methods lfdt -S translator.lr_decay=cosine
"""

import lfdt.numerics  # noqa: F401

import argparse
import csv
import datetime
import json
import os
import shutil
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import yaml

from lfdt import data, evaluation, layout, methods, numerics, parallel, stage
from lfdt.box_push_jobs import common
from lfdt.box_push_jobs.bc import bc_job
from lfdt.box_push_jobs.evaluate import evaluate_job
from lfdt.box_push_jobs.track import track_job
from lfdt.box_push_jobs.translator import translator_job
from lfdt.config import validate_params
from lfdt.csvlog import append_rows

ROOT = Path(__file__).resolve().parents[1]
DEV_SEEDS = list(range(40, 50))
"""The development seed block of these trials (the evaluation seeds are grid.seeds, 100-109)."""


def set_key(doc: dict, dotted: str, value: str) -> None:
    keys = dotted.split(".")
    for k in keys[:-1]:
        if k not in doc:
            raise SystemExit(f"-S {dotted}: no key {k!r} in params.yaml")
        doc = doc[k]
    if keys[-1] not in doc:
        raise SystemExit(f"-S {dotted}: no key {keys[-1]!r} in params.yaml")
    doc[keys[-1]] = yaml.safe_load(value)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--name", required=True)
    ap.add_argument("--demos", type=int, nargs="+", default=[100])
    ap.add_argument("--methods", nargs="+", default=["lfdt", "bc_no_translation"])
    ap.add_argument("--seeds", type=int, nargs="+", default=DEV_SEEDS)
    ap.add_argument("-S", "--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--hypothesis", default="", help="what the trial tests, written before it runs")
    ap.add_argument("--keep", action="store_true", help="keep dev/<name>/ (models and data) afterwards")
    ap.add_argument("--reuse-translations", metavar="TRIAL",
                    help="take the translated demonstrations of an earlier trial kept with --keep (its translator "
                         "params must be this trial's) instead of training translators: for BC-only changes")
    ap.add_argument("--bc-seed-offset", type=int, default=0,
                    help="with --reuse-translations: train BC with seed + OFFSET on the same data (translations and "
                         "raw subsets of the seed): what BC's own seed does")
    ap.add_argument("--baseline-from", help="pair with BC without translation of this earlier trial (same seeds, "
                                            "same start states; it does not depend on the translator's params)")
    ap.add_argument("--demos-dir", type=Path, default=ROOT / "data/demos",
                    help="the demonstrations (R1H.parquet, HR2.parquet): the pipeline's, or a candidate protocol's")
    ap.add_argument("--random-dir", type=Path, default=ROOT / "data/random", help="the random motion of X and Y")
    ap.add_argument("--dynamics-dir", type=Path, default=ROOT / "models/dynamics", help="F and F^-1 of Y")
    args = ap.parse_args()
    if set(args.seeds) & set(stage.params(ROOT / "params.yaml").grid.seeds):
        raise SystemExit("tools/dev_trial.py: the evaluation seeds (grid.seeds) are not for development")
    root = ROOT / "dev" / args.name
    shutil.rmtree(root, ignore_errors=True)
    root.mkdir(parents=True)
    doc = yaml.safe_load((ROOT / "params.yaml").read_text())
    for kv in args.set:
        key, _, value = kv.partition("=")
        set_key(doc, key, value)
    doc["grid"]["seeds"] = args.seeds
    doc["evaluation"]["start_states"] = "development"
    doc["evaluation"]["videos"] = 0
    p = validate_params(doc)
    args.params_doc = doc
    params_path = root / "params.yaml"
    params_path.write_text(yaml.safe_dump(doc, sort_keys=False))
    os.environ["DVC_EXP_NAME"] = f"dev-{args.name}"  # the MLflow runs' tag
    dirs = {"demos_dir": args.demos_dir.resolve(), "random_dir": args.random_dir.resolve(),
            "dynamics_dir": args.dynamics_dir.resolve(), "translators_dir": root / "translators",
            "bc_data_dir": root / "bc_train", "policies_dir": root / "policies", "videos_dir": root / "videos"}
    t0 = time.perf_counter()
    wanted = [methods.get(m) for m in args.methods]
    translators = sorted({m.translator for m in wanted if m.translator}, key=list(methods.METHODS).index)
    rows, diag_rows = {}, []
    if args.bc_seed_offset and not args.reuse_translations:
        raise SystemExit("--bc-seed-offset needs --reuse-translations")
    if args.reuse_translations:
        src = ROOT / "dev" / args.reuse_translations / "bc_train"
        if not src.exists():
            raise SystemExit(f"--reuse-translations: {src} does not exist (run that trial with --keep)")
        shutil.copytree(src, dirs["bc_data_dir"])
        translators = []
        if args.bc_seed_offset:
            for group in dirs["bc_data_dir"].iterdir():
                for s in args.seeds:
                    shutil.copytree(group / f"s{s}", group / f"s{s + args.bc_seed_offset}")
    for n in args.demos:
        for tm in translators:
            cfgs = common.configs(tm, n, args.seeds, p, **dirs)
            res = common.flatten(parallel.run_jobs(translator_job, common.groups(cfgs, p.grid.workers),
                                                   p.grid.workers, desc=f"translator {tm}-d{n}", unit="seed-it"))
            for r in res:
                diag_rows.append({"method": tm, "demos": n, "stage": "translator", **_flat(r["metrics"])})
        for m in wanted:
            bc_seeds = [s + args.bc_seed_offset for s in args.seeds]
            cfgs = common.configs(m.name, n, bc_seeds, p, **dirs)
            if m.data == "raw" and args.bc_seed_offset:
                pass  # the seed's own raw subsets, copied above
            elif m.data == "raw":
                for cfg in cfgs:
                    for pairing in layout.PAIRINGS:
                        path = dirs["demos_dir"] / f"{pairing}.parquet"
                        eps = data.demo_subset(path, n, cfg.seed, pairing)
                        table = pq.read_table(path)
                        keep = table.column("episode_index").to_numpy()
                        data.write_table(table.filter(np.isin(keep, eps)),
                                         cfg.dir(dirs["bc_data_dir"]) / f"raw_{pairing}.parquet")
            elif m.data == "executed":
                parallel.run_jobs(track_job, cfgs, p.grid.workers, desc=f"track {m.name}-d{n}")
            res = common.flatten(parallel.run_jobs(bc_job, common.groups(cfgs, p.grid.workers), p.grid.workers,
                                                   desc=f"BC {m.name}-d{n}", unit="seed-it"))
            for r in res:
                diag_rows.append({"method": m.name, "demos": n, "stage": "bc", **_flat(r["metrics"])})
            res = common.flatten(parallel.run_jobs(evaluate_job, common.groups(cfgs, p.grid.workers),
                                                   p.grid.workers, desc=f"evaluate {m.name}-d{n}", unit="trial"))
            outcomes = np.array([[t["success"] for t in r["trials"]] for r in res], dtype=float)
            path = np.array([[t["path_success"] for t in r["trials"]] for r in res], dtype=float)
            rows[(m.name, n)] = {"": outcomes, "path_": path}
            save_outcomes(args.name, m.name, n, bc_seeds, outcomes)
            save_outcomes(args.name, m.name, n, bc_seeds, path, rule="path")
            for r, o, po in zip(res, outcomes, path):
                diag_rows.append({"method": m.name, "demos": n, "stage": "evaluate", "seed": r["metrics"]["seed"],
                                  "success_rate": float(o.mean()), "path_success_rate": float(po.mean()),
                                  "max_abs_yaw_median": float(np.median([t["max_abs_yaw_rad"] for t in r["trials"]]))})
            print(f"{m.name}-d{n}: {100 * outcomes.mean():.1f} % (per seed "
                  f"{', '.join(f'{100 * x:.0f}' for x in outcomes.mean(axis=1))}); path rule "
                  f"{100 * path.mean():.1f} % (per seed {', '.join(f'{100 * x:.0f}' for x in path.mean(axis=1))})",
                  file=sys.stderr)
    write_results(args, rows, diag_rows, time.perf_counter() - t0)
    print(json.dumps({f"{m}-d{n}": [round(100 * o[k].mean(), 1) for k in ("", "path_")] for (m, n), o in rows.items()}),
          file=sys.stderr)
    if not args.keep:
        shutil.rmtree(root, ignore_errors=True)


FIELDS = ["date", "trial", "hypothesis", "changes", "method", "demos", "seeds", "start_states", "success_pct",
          "ci_low_pct", "ci_high_pct", "worst_seed_pct", "per_seed_pct", "diff_vs_bc_no_translation_pct",
          "diff_ci_low_pct", "diff_ci_high_pct", "cpu_model", "numerics", "wall_min", "demos_dir", "path_success_pct",
          "path_ci_low_pct", "path_ci_high_pct", "path_worst_seed_pct", "path_per_seed_pct",
          "path_diff_vs_bc_no_translation_pct", "path_diff_ci_low_pct", "path_diff_ci_high_pct",
          "f_push_across", "f_push_angle"]
"""The columns of docs/experiments/trials.csv (those from demos_dir on were added with the path rule; earlier rows
leave them empty: those trials ran on data/demos and before the rule). ``f_push_*``: F's error on two-arm pushes of
the box, across it and in yaw, as a share of predicting no change (:func:`lfdt.dynamics.object_frame_ratios`)."""

OUTCOMES = ROOT / "docs" / "experiments" / "outcomes"
"""Every trial's 0/1 outcomes, one file per (trial, method, demos): a later trial pairs with them."""


def _outcome_file(trial: str, method: str, demos: int, rule: str) -> Path:
    return OUTCOMES / f"{trial}_{method}-d{demos}{'' if rule == 'end' else '_' + rule}.csv"


def save_outcomes(trial: str, method: str, demos: int, seeds: list[int], outcomes: np.ndarray,
                  rule: str = "end") -> None:
    """One trial's 0/1 outcomes by the end-state rule ('end') or the path rule ('path')."""
    OUTCOMES.mkdir(parents=True, exist_ok=True)
    with _outcome_file(trial, method, demos, rule).open("w") as f:
        f.write("seed,outcomes\n")
        for s, o in zip(seeds, outcomes):
            f.write(f"{s},{''.join(str(int(x)) for x in o)}\n")


def load_outcomes(trial: str, method: str, demos: int, seeds: list[int], rule: str = "end") -> np.ndarray | None:
    path = _outcome_file(trial, method, demos, rule)
    if not path.exists():
        return None
    rows = dict(line.strip().split(",") for line in path.read_text().splitlines()[1:])
    if sorted(int(s) for s in rows) != sorted(seeds):
        return None
    return np.array([[int(c) for c in rows[str(s)]] for s in seeds], dtype=float)


def widen(path: Path, fields: list[str]) -> None:
    """Give a trials file written before columns were added to FIELDS those columns (empty in its rows); any other
    header is left for :func:`lfdt.csvlog.append_rows` to refuse."""
    if not path.exists():
        return
    with path.open(newline="") as f:
        rows = list(csv.reader(f))
    if not rows or rows[0] == fields or rows[0] != fields[:len(rows[0])]:
        return
    tmp = path.with_suffix(".csv.tmp")
    with tmp.open("w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(fields)
        w.writerows(r + [""] * (len(fields) - len(r)) for r in rows[1:])
    tmp.replace(path)


def push_ratios(dynamics_dir: Path, params_doc: dict) -> dict:
    """F of ``dynamics_dir`` on two-arm pushes of the box (the probe of ``stages/fit_dynamics.py``)."""
    from lfdt.config import validate_params
    from lfdt.dynamics import load_models, object_frame_ratios
    from lfdt.tasks.box_push.random_motion import push_probe

    p = validate_params(params_doc)
    return object_frame_ratios(load_models(dynamics_dir / common.DYNAMICS_FILE), *push_probe(p.env), common.LAYOUT)


def _flat(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flat(v, f"{prefix}{k}/"))
        elif isinstance(v, (int, float, str, bool)) or v is None:
            out[f"{prefix}{k}"] = v
    return out


def write_results(args, rows: dict, diag_rows: list[dict], wall: float) -> None:
    out_dir = ROOT / "docs" / "experiments"
    out_dir.mkdir(parents=True, exist_ok=True)
    trials = out_dir / "trials.csv"
    fields = FIELDS
    info = numerics.describe()
    f_push = push_ratios(args.dynamics_dir.resolve(), args.params_doc)
    out = []
    for (m, n), by_rule in rows.items():
        row = {"date": datetime.date.today().isoformat(), "trial": args.name, "hypothesis": args.hypothesis,
               "changes": " ".join(args.set + ([f"BC seed = seed + {args.bc_seed_offset}"]
                                               if args.bc_seed_offset else [])), "method": m, "demos": n,
               "seeds": " ".join(map(str, args.seeds)), "start_states": "development",
               "demos_dir": os.path.relpath(args.demos_dir.resolve(), ROOT),
               "f_push_across": f"{f_push['across']:.3f}", "f_push_angle": f"{f_push['angle']:.3f}",
               "cpu_model": info["cpu_model"], "numerics": info["numerics"], "wall_min": f"{wall / 60:.1f}"}
        for pre, o in by_rule.items():
            lo, hi = evaluation.seed_state_interval(o)
            per = o.mean(axis=1)
            base = rows.get(("bc_no_translation", n), {}).get(pre)
            if base is None and args.baseline_from:
                base = load_outcomes(args.baseline_from, "bc_no_translation", n, args.seeds,
                                     "path" if pre else "end")
            dlo = dhi = diff = ""
            if base is not None and m != "bc_no_translation":
                d = o - base
                diff = f"{100 * d.mean():.1f}"
                a, b = evaluation.paired_difference_interval(o, base)
                dlo, dhi = f"{100 * a:.1f}", f"{100 * b:.1f}"
            row.update({f"{pre}success_pct": f"{100 * o.mean():.1f}", f"{pre}ci_low_pct": f"{100 * lo:.1f}",
                        f"{pre}ci_high_pct": f"{100 * hi:.1f}", f"{pre}worst_seed_pct": f"{100 * per.min():.1f}",
                        f"{pre}per_seed_pct": " ".join(f"{100 * x:.1f}" for x in per),
                        f"{pre}diff_vs_bc_no_translation_pct": diff, f"{pre}diff_ci_low_pct": dlo,
                        f"{pre}diff_ci_high_pct": dhi})
        out.append(row)
    widen(trials, fields)
    append_rows(trials, fields, [[str(r.get(f, "")) for f in fields] for r in out])  # all rows in one write
    keys = sorted({k for r in diag_rows for k in r})
    if not keys:
        return
    with (out_dir / f"{args.name}_seeds.csv").open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(diag_rows)


if __name__ == "__main__":
    main()
