"""DVC stage: every trained BC policy (Table I's and the twin's) as an MLflow model in the run that trained it,
registered under its task, method and demo count, one version per seed with the alias ``seed<N>``
(:mod:`lfdt.policy_models`). Writes the models' URIs (reports/models.csv) and their versions (runs/models.json)."""

import lfdt.numerics  # noqa: F401  (first: pins the numeric code paths before numpy, torch or mujoco load)

import json
from pathlib import Path

from lfdt import mlflow_runs, policy_models, stage, twin
from lfdt.tasks import registry

TABLE_I_TASK = "box_push"
"""The task of Table I's policies (the twin's are named by params ``twin.tasks``)."""

REQUIREMENTS = ("torch", "numpy", "pandas", "mujoco", "gymnasium", "mlflow", "pyarrow")
"""The libraries a policy model needs besides this package (``make setup`` installs them all), at the versions
that trained it."""


def requirements() -> list[str]:
    """``name==version`` of :data:`REQUIREMENTS` as installed here."""
    from importlib.metadata import version

    return [f"{name}=={version(name)}" for name in REQUIREMENTS]


def seed_runs(book: Path) -> dict[int, str]:
    """Seed -> MLflow run id from a matrix or twin stage's bookkeeping file (runs/...json)."""
    if not book.exists():
        raise SystemExit(f"error: {book} is missing: the stage that trained these policies has not run (`dvc repro`)")
    seeds = json.loads(book.read_text()).get("seeds", {})
    return {int(s): v["mlflow_run_id"] for s, v in seeds.items()}


def run() -> None:
    ap = stage.parser(__doc__, {"policies": "Table I's policies, <method>-d<demos>/s<seed>/",
                                "bc-runs": "the BC stage's bookkeeping, <method>-d<demos>.json",
                                "twin-models": "the twin's models, <task>/s<seed>/<method>/",
                                "twin-runs": "the twin stages' bookkeeping, <task>_train.json",
                                "out": "the models' URIs (CSV)", "versions": "their registered versions (JSON)"})
    args = ap.parse_args()
    p = stage.params(args.params)
    mlflow_runs.experiment_id()  # sets the tracking store (and checks that it answers)
    reqs = requirements()
    jobs = []  # (policy folder, run id, task, method, seed, demos, action bounds)
    for method in p.grid.bc_methods:
        for demos in p.grid.demos:
            runs = seed_runs(args.bc_runs / f"{method}-d{demos}.json")
            bounds = registry.get(TABLE_I_TASK).action_bounds
            jobs += [(args.policies / f"{method}-d{demos}" / f"s{s}", runs[s], TABLE_I_TASK, method, s, demos, bounds)
                     for s in p.grid.seeds]
    for task in p.twin.tasks:
        runs = seed_runs(args.twin_runs / f"{task}_train.json")
        bounds = registry.get(task).action_bounds
        jobs += [(args.twin_models / task / f"s{s}" / method, runs[s], task, method, s, None, bounds)
                 for s in p.twin.seeds for method in twin.TWIN_METHODS]
    missing = [j for j in jobs if not j[0].is_dir()]
    if missing:
        raise SystemExit(f"error: no trained policy in {missing[0][0]} ({len(missing)} missing; `dvc repro` trains "
                         "them)")
    mlflow_runs.require_runs([j[1] for j in jobs], "that trained these policies")
    examples = {task: policy_models.input_example(task) for task in {j[2] for j in jobs}}
    rows = []
    with stage.progress(len(jobs), "registering policies", "model") as bar:
        for folder, rid, task, method, seed, demos, bounds in jobs:
            rows.append(policy_models.log_policy(folder, run_id=rid, task=task, method=method, seed=seed,
                                                 demos=demos, action_bounds=bounds, example=examples[task],
                                                 requirements=reqs))
            bar.update(1)
    stage.write_csv(args.out, [{k: r[k] for k in ("task", "method", "demos", "seed", "uri")} for r in rows])
    stage.write_json(args.versions, {"models": [{k: r[k] for k in ("uri", "name", "version", "run_id")}
                                                for r in rows]})
    print(f"registered {len(rows)} policies; e.g. `mlflow models predict -m {rows[0]['uri']} ...` "
          f"(README: MLflow), {args.out}")


if __name__ == "__main__":
    stage.main(run)
