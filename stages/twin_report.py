"""DVC stage: reports/twin_runs.csv and reports/twin.md, our results beside the paper's real-robot numbers, and the
headline success rates as the metrics file reports/twin.json."""

import lfdt.numerics  # noqa: F401  (first: pins the numeric code paths before numpy, torch or mujoco load)

import json

import numpy as np

from lfdt import methods, mlflow_runs, mlflow_views, stage, twin
from lfdt.evaluation import seed_state_interval, wilson_interval


def interval(trials: list[dict]) -> tuple[float, float]:
    """95 % interval of the success rate: seeds and start states both random when every seed ran the same start
    states (the twin), else a Wilson interval over all trials (deploy logs of the robots)."""
    seeds = sorted({r["seed"] for r in trials})
    per = [sorted((r["trial"], r["success"]) for r in trials if r["seed"] == s) for s in seeds]
    if len(seeds) > 1 and all([t for t, _ in x] == [t for t, _ in per[0]] for x in per):
        return seed_state_interval(np.array([[ok for _, ok in x] for x in per], dtype=float))
    return wilson_interval(sum(r["success"] for r in trials), len(trials))


def run() -> None:
    ap = stage.parser(__doc__, {"twin-reports": "the twin stages' reports, <task>_<data|train|eval>.json",
                                "out-dir": "where twin_runs.csv and twin.md go"})
    args = ap.parse_args()
    p = stage.params(args.params).twin
    rows, lines, headline = [], [], {}
    source = "MuJoCo twin" if p.backend == "sim" else "the robots"
    if p.backend == "sim" and p.start_states == "development":
        source += ", development start states: for choosing settings, not results"
    lines += [f"# Real-robot tasks ({source})", "",
              "| task | method | ours | successes | per seed | 95 % interval | paper (real robots) |",
              "| --- | --- | --- | --- | --- | --- | --- |"]
    for task in p.tasks:
        ev = json.loads((args.twin_reports / f"{task}_eval.json").read_text())
        rows += [{k: r[k] for k in ("task", "method", "seed", "trial", "success")} for r in ev["per_trial"]]
        for method in twin.TWIN_METHODS:
            trials = [r for r in ev["per_trial"] if r["method"] == method]
            k, n = sum(r["success"] for r in trials), len(trials)
            seeds = sorted({r["seed"] for r in trials})
            per_seed = ", ".join(f"{100 * np.mean([r['success'] for r in trials if r['seed'] == s]):.0f}"
                                 for s in seeds)
            lo, hi = interval(trials)
            headline.setdefault(task, {})[method] = {"success_rate": round(k / max(n, 1), 4),
                                                     "ci_low": round(lo, 4), "ci_high": round(hi, 4)}
            pk, pn = twin.PAPER_REAL[task][method]
            lines.append(f"| {task} | {methods.get(method).title} | **{100 * k / max(n, 1):.0f} %** | {k}/{n} | "
                         f"{per_seed} | {100 * lo:.0f}–{100 * hi:.0f} % | {pk}/{pn} |")
    lines += ["", f"Data per task and seed: {p.random_samples} random-motion samples per domain, "
              f"{p.demos_per_pairing} + {p.demos_per_pairing} demonstrations; {p.trials} trials per method and seed "
              f"from the same start states; seeds {', '.join(map(str, p.seeds))} (each its own data, dynamics, "
              "translator and BC; 'per seed' in %). The interval counts both the seeds and the start states as "
              "random. Paper: Kobayashi et al. 2023, §IV-E (10 trials on the real robots)."]
    runs_csv, md = args.out_dir / "twin_runs.csv", args.out_dir / "twin.md"
    stage.write_csv(runs_csv, rows)
    md.write_text("\n".join(lines) + "\n")
    # one parent run for the twin: it carries the report and adopts the runs behind it
    children = [i for task in p.tasks for kind in ("data", "train", "eval")
                for i in stage.run_ids(stage.read_report(args.twin_reports / f"{task}_{kind}.json"))]
    params = {"twin": {"seeds": p.seeds, "trials": p.trials, "backend": p.backend}}
    # the headline metrics (`dvc metrics show`), their run id and wall time in runs/twin.json
    with stage.frame(args.out_dir / "twin.json", "twin_report", params, tags={"pipeline_parent": "true"},
                     run_name=mlflow_runs.pipeline_run_name("twin")) as f:
        parent = f.run
        f.report = headline
        parent.artifact(md)
        parent.artifact(runs_csv)
        f.metrics({f"{task}/{method}/success_rate": v["success_rate"] for task, m in headline.items()
                   for method, v in m.items()})
        mlflow_runs.adopt_children(parent.run_id, children)
        parent.dict({"runs": list(dict.fromkeys(children))}, "children.json")  # kept when a newer parent adopts them
    mlflow_views.install()  # the twin's view shows this parent's runs (the report stage may have run before it)
    print("\n".join(lines))


if __name__ == "__main__":
    stage.main(run)
