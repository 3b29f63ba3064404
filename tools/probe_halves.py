"""The premise of Table I's BC without translation, probed: what do its two cloned robot halves do that the robots'
programs do not? On the policies of a development trial kept with ``--keep`` (``dev/<trial>/policies``), each variant
runs every development seed's policy from the development start states and scores both rules:

* ``clones``: both clones, as evaluated (BC without translation);
* ``clone1+program2`` / ``program1+clone2``: one clone beside the other robot's program (a take drawn per start
  state), which never adapts: does the clone adapt to its partner?
* ``yaw-frozen`` / ``yaw-zero``: both clones, the box yaw they are given held at its start value / at 0: do they
  coordinate through the box's yaw?

    python tools/probe_halves.py --trial i37-base --demos 100

writes ``docs/experiments/probe_halves_<trial>_d<demos>.json`` (per seed and mean, both rules; CPU and date).
"""

import lfdt.numerics  # noqa: F401

import argparse
import datetime
import json
from pathlib import Path

import numpy as np

from lfdt import numerics, stage
from lfdt.bc import BCPolicy
from lfdt.box_push_jobs.common import LAYOUT
from lfdt.evaluation import evaluation_seeds
from lfdt.tasks.box_push.env import BoxPushEnv
from lfdt.tasks.box_push.programmed import make_robot

ROOT = Path(__file__).resolve().parents[1]
VARIANTS = ("clones", "clone1+program2", "program1+clone2", "yaw-frozen", "yaw-zero")


def run_variant(variant: str, policy: BCPolicy, p, trials: int) -> np.ndarray:
    """(trials, 2) outcomes (end-state rule, path rule) of one variant of one seed's policy."""
    iyaw = LAYOUT.state_columns("Y").index("box.yaw")
    env = BoxPushEnv("Y", p.env)
    n1 = env.scene.nq_arm[0]
    slots = (slice(0, n1), slice(n1, 2 * n1))
    out = []
    for seed in evaluation_seeds(trials, "development"):
        obs, _ = env.reset(seed=seed)
        yaw0 = obs[iyaw]
        qpos = env.data.qpos.copy()
        # a take of each robot's program, drawn from the start scene as the demonstrations draw theirs
        programs = [make_robot("Y", arm.name, qpos[sl].copy(), qpos[env.scene.box_qpos].copy(), p.env,
                               p.demos.program, np.random.default_rng(seed)) for arm, sl in zip(env.scene.arms, slots)]
        done = False
        while not done:
            seen = obs.copy()
            if variant == "yaw-frozen":
                seen[iyaw] = yaw0
            elif variant == "yaw-zero":
                seen[iyaw] = 0.0
            a = policy(seen)
            if variant == "clone1+program2":
                a[slots[1]] = programs[1].action(env.data.qpos[slots[1]].copy())
            elif variant == "program1+clone2":
                a[slots[0]] = programs[0].action(env.data.qpos[slots[0]].copy())
            obs, _, term, trunc, info = env.step(a)
            done = term or trunc
        out.append((bool(term), bool(term) and info["is_path_success"]))
    return np.array(out, dtype=float)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--trial", required=True, help="a development trial run with --keep and bc_no_translation")
    ap.add_argument("--demos", type=int, required=True)
    ap.add_argument("--trials", type=int, default=100, help="development start states per seed")
    ap.add_argument("--variants", nargs="+", choices=VARIANTS, default=list(VARIANTS))
    args = ap.parse_args()
    root = ROOT / "dev" / args.trial
    p = stage.params(root / "params.yaml")
    group = root / "policies" / f"bc_no_translation-d{args.demos}"
    seed_dirs = sorted(group.glob("s*"), key=lambda d: int(d.name[1:]))
    if not seed_dirs:
        raise SystemExit(f"no BC without translation policies in {group} (run the trial with --keep)")
    report: dict = {"trial": args.trial, "demos": args.demos, "start_states": "development",
                    "trials_per_seed": args.trials, "seeds": [int(d.name[1:]) for d in seed_dirs],
                    "cpu_model": numerics.describe()["cpu_model"], "date": datetime.date.today().isoformat(),
                    "variants": {}}
    for variant in args.variants:
        per_seed = np.array([run_variant(variant, BCPolicy.load(d, LAYOUT, (-1.0, 1.0))[0], p, args.trials).mean(0)
                             for d in seed_dirs])
        report["variants"][variant] = {
            "end_pct": round(100 * float(per_seed[:, 0].mean()), 1),
            "path_pct": round(100 * float(per_seed[:, 1].mean()), 1),
            "per_seed_end_pct": [round(100 * float(x), 1) for x in per_seed[:, 0]],
            "per_seed_path_pct": [round(100 * float(x), 1) for x in per_seed[:, 1]]}
        print(variant, report["variants"][variant], flush=True)
    out = ROOT / "docs" / "experiments" / f"probe_halves_{args.trial}_d{args.demos}.json"
    out.write_text(json.dumps(report, indent=1) + "\n")
    print(f"wrote {out.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
