"""Ten seeds trained as one stacked model against ten seeds one at a time, on one core, in one run.

translator: lfdt.translation.training.train_translators with a stack of 10 members against 10 calls with one each
            (the default translator config: batch 128, G and D of 256 x 2, F and F^-1 of 256 x 3);
bc:         lfdt.bc.train_members with 10 members against 10 calls with one each (batch 32, 256 x 2);
evaluate:   200 trials of 10 policies stepped in lockstep (one policy call per control step for all) against each
            trial on its own (one call per step and trial).

Throughput is seed-iterations (or trials) per second; the ratio stacked / one at a time is the speed-up (the issue's
goal: >= 4). Runs alternate, medians of --repeats. Writes benchmarks/results/stack_throughput.json.
"""

import lfdt.numerics  # noqa: F401

import argparse
import json
import statistics
import time
from pathlib import Path

import numpy as np
import pandas as pd
import torch

from lfdt import bc, evaluation, layout, numerics
from lfdt.box_push_jobs.evaluate import box_push_trials
from lfdt.box_push_jobs.translator import box_push_kinematics
from lfdt.config import BCConfig, EnvConfig, TranslatorConfig
from lfdt.dynamics import DynamicsModels
from lfdt.tasks.box_push import columns as box_columns
from lfdt.translation.training import Member, train_translators
from lfdt.translation.transitions import Transitions

TL = box_columns.BOX_PUSH


def fake_transitions(n: int, dim: int, rng: np.random.Generator) -> Transitions:
    x = rng.normal(size=(n, dim)).astype(np.float32)
    return Transitions(x=x, x2=x + 0.01, episode=np.arange(n) // 20, frame=np.arange(n) % 20, x_prev=x)


def translator_rate(seeds: int, stacked: bool, iters: int) -> float:
    rng = np.random.default_rng(0)
    dyn = DynamicsModels(19, 6, [256, 256, 256])
    rand = {p: fake_transitions(20_000, 21, rng) for p in layout.PAIRINGS}
    y = rng.normal(size=(20_000, 19)).astype(np.float32)
    members = [Member({p: fake_transitions(2_000, 21, rng) for p in layout.PAIRINGS}, s)
               for s in range(seeds)]
    cfg = TranslatorConfig(iterations=iters, select_every=10 ** 6, log_every=10 ** 6)
    kin = box_push_kinematics(EnvConfig())
    t0 = time.perf_counter()
    for group in ([members] if stacked else [[m] for m in members]):
        train_translators(group, rand, y, dyn, cfg, tl=TL, kinematics=kin)
    return seeds * iters / (time.perf_counter() - t0)


def bc_tasks(seeds: int) -> list[bc.BCTask]:
    rng = np.random.default_rng(1)
    out = []
    for _ in range(seeds):
        df = pd.DataFrame(rng.normal(size=(9_000, 25)).astype(np.float32),
                          columns=[layout.STATE_PREFIX + c for c in TL.state_columns("Y")] +
                          [layout.ACTION_PREFIX + c for c in TL.action_columns("Y")])
        df["episode_index"] = np.arange(9_000) // 25
        out.append(bc.tasks_for("lfdt", translated=df, tl=TL)[0])
    return out


def bc_rate(seeds: int, stacked: bool, iters: int) -> float:
    tasks = bc_tasks(seeds)
    cfg = BCConfig(iterations=iters, eval_every=10 ** 6)
    t0 = time.perf_counter()
    if stacked:
        bc.train_members(tasks, cfg, list(range(seeds)))
    else:
        for s, t in enumerate(tasks):
            bc.train_member(t, cfg, s)
    return seeds * iters / (time.perf_counter() - t0)


def evaluate_rate(seeds: int, stacked: bool, trials: int) -> float:
    members, _ = bc.train_members(bc_tasks(seeds), BCConfig(iterations=5, eval_every=10 ** 6), list(range(seeds)))
    policies = [bc.BCPolicy([m], TL) for m in members]
    env_cfg = EnvConfig()
    t0 = time.perf_counter()
    if stacked:
        box_push_trials(bc.StackedPolicies(policies), seeds, env_cfg, trials, purpose="development")
    else:
        from lfdt.tasks.box_push.task import TASK

        for pol in policies:
            evaluation.rollout_trials(pol, lambda record: TASK.make_env("Y", env_cfg), trials, purpose="development")
    return seeds * trials / (time.perf_counter() - t0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--iterations", type=int, default=200, help="translator iterations (BC: 10x)")
    ap.add_argument("--trials", type=int, default=40)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/stack_throughput.json"))
    args = ap.parse_args()
    torch.set_num_threads(1)
    rates: dict[str, dict[str, list[float]]] = {}
    jobs = {"translator": (translator_rate, args.iterations), "bc": (bc_rate, 10 * args.iterations),
            "evaluate": (evaluate_rate, args.trials)}
    for _ in range(args.repeats):
        for name, (fn, n) in jobs.items():
            for stacked in (True, False):
                r = fn(args.seeds, stacked, n)
                rates.setdefault(name, {}).setdefault("stacked" if stacked else "one_at_a_time", []).append(r)
                print(f"{name} {'stacked' if stacked else 'one at a time'}: {r:.1f}/s", flush=True)
    info = numerics.describe()
    out = {"seeds": args.seeds, "cpu_model": info["cpu_model"], "numerics": info["numerics"],
           "date": time.strftime("%Y-%m-%d"), "threads": 1, "repeats": args.repeats}
    for name, r in rates.items():
        med = {k: statistics.median(v) for k, v in r.items()}
        out[name] = {"per_s": med, "speedup": med["stacked"] / med["one_at_a_time"],
                     "unit": "trials" if name == "evaluate" else "seed-iterations"}
        print(f"{name}: stacked {med['stacked']:.1f}/s, one at a time {med['one_at_a_time']:.1f}/s, "
              f"speed-up {out[name]['speedup']:.2f} (goal 4)")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
