"""Development: the mean action of several BC policies per seed (kept development trials that differ only in BC's
seed), evaluated from the development start states like one policy.

    python tools/dev_ensemble.py --name ens5 --trials bcseed-0 bcseed-1000 bcseed-2000 bcseed-3000 bcseed-4000 \
        --offsets 0 1000 2000 3000 4000 --method lfdt --demos 100

Each trial must have been run with ``--keep`` (its policies in ``dev/<trial>/policies``); the policy of seed s in the
trial of offset o is ``<method>-d<demos>/s<s + o>``. The ensemble's action is the mean of the members' actions,
clipped to the action space. Appends a row to docs/experiments/trials.csv and saves the outcomes, as
``tools/dev_trial.py`` does.
"""

import lfdt.numerics  # noqa: F401

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from lfdt import bc
from lfdt.box_push_jobs.evaluate import box_push_trials
from lfdt.config import EnvConfig
from lfdt.tasks.box_push import columns as box_columns

sys.path.insert(0, str(Path(__file__).parent))
from dev_trial import DEV_SEEDS, ROOT, save_outcomes, write_results  # noqa: E402


class MeanOfPolicies:
    """``k`` policies per seed acting as one: the mean of their actions (clipped), one stacked call for all."""

    def __init__(self, members: list[list[bc.BCPolicy]]):
        self.n, self.k = len(members), len(members[0])
        self.stack = bc.StackedPolicies([p for per_seed in members for p in per_seed])
        self.stack.action_bounds = None  # clip the mean, not each member
        self.bounds = members[0][0].action_bounds

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        rep = np.repeat(obs, self.k, axis=0)
        act = self.stack(rep).reshape(self.n, self.k, *obs.shape[1:2], -1).mean(axis=1)
        return act if self.bounds is None else np.clip(act, *self.bounds)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--name", required=True)
    ap.add_argument("--trials", nargs="+", required=True)
    ap.add_argument("--offsets", type=int, nargs="+", required=True)
    ap.add_argument("--method", default="lfdt")
    ap.add_argument("--demos", type=int, default=100)
    ap.add_argument("--seeds", type=int, nargs="+", default=DEV_SEEDS)
    ap.add_argument("--hypothesis", default="")
    args = ap.parse_args()
    if len(args.trials) != len(args.offsets):
        raise SystemExit("--trials and --offsets must pair up")
    t0 = time.perf_counter()
    tl = box_columns.BOX_PUSH
    members = [[bc.BCPolicy.load(ROOT / "dev" / t / "policies" / f"{args.method}-d{args.demos}" / f"s{s + o}", tl)[0]
                for t, o in zip(args.trials, args.offsets)] for s in args.seeds]
    res = box_push_trials(MeanOfPolicies(members), len(args.seeds), EnvConfig(), 200, purpose="development")
    outcomes = np.array([[t["success"] for t in r] for r in res], dtype=float)
    save_outcomes(args.name, args.method, args.demos, args.seeds, outcomes)
    args.set = [f"mean action of {len(args.trials)} BC seeds ({', '.join(args.trials)})"]
    args.bc_seed_offset, args.baseline_from = 0, None
    write_results(args, {(args.method, args.demos): outcomes}, [], time.perf_counter() - t0)
    print(f"{args.method}-d{args.demos} ensemble of {len(args.trials)}: {100 * outcomes.mean():.1f} % (per seed "
          f"{', '.join(f'{100 * x:.0f}' for x in outcomes.mean(axis=1))})", file=sys.stderr)


if __name__ == "__main__":
    main()
