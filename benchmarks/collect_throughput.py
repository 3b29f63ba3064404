"""Random-motion collection throughput as a ratio to raw ``mj_step`` throughput of the same model, same run.

raw:        one MjData, ``mj_step(model, data, nstep=frame_skip)`` per control step with a new random
            command each step (no Python work besides setting ctrl): physics steps/s / frame_skip
            gives the raw control-step rate.
gymnasium:  ``BoxPushEnv.step`` in a Python loop (observation, reward and info computed).
collect:    ``lfdt.tasks.box_push.random_motion.collect_random`` (batched ``mujoco.rollout`` on ``random.threads``
            threads, plus drawing commands and building the Arrow table): transitions/s.

Bar (issue 2): collect / raw >= 0.8. Writes benchmarks/results/collect_throughput.json.
"""

from __future__ import annotations

import lfdt.numerics  # noqa: F401  (first: pins the numeric code paths before numpy, torch or mujoco load)

import argparse
import json
import os
import platform
import time
from pathlib import Path

import mujoco
import numpy as np

from lfdt.config import load_params
from lfdt.tasks.box_push.env import BoxPushEnv, BoxPushModel
from lfdt.tasks.box_push.random_motion import collect_random


def raw_rate(domain: str, cfg, steps: int) -> float:
    scene = BoxPushModel(domain, cfg)
    m, d = scene.model, mujoco.MjData(scene.model)
    rng = np.random.default_rng(0)
    d.qpos[:] = scene.sample_initial_qpos(rng)
    ctrl = rng.uniform(-1, 1, size=(steps, m.nu))
    t0 = time.perf_counter()
    for i in range(steps):
        d.ctrl[:] = ctrl[i]
        mujoco.mj_step(m, d, nstep=cfg.frame_skip)
    return steps / (time.perf_counter() - t0)


def gym_rate(domain: str, cfg, steps: int) -> float:
    env = BoxPushEnv(domain, cfg)
    env.reset(seed=0)
    acts = np.random.default_rng(0).uniform(-1, 1, size=(steps, env.action_space.shape[0]))
    t0 = time.perf_counter()
    for a in acts:
        env.step(a)
    return steps / (time.perf_counter() - t0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--transitions", type=int, default=100_000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", default="benchmarks/results/collect_throughput.json")
    args = ap.parse_args()
    p = load_params("params.yaml")
    rows = []
    for domain in ("Y", "R1H", "HR2"):
        rcfg = p.random.model_copy(update={"transitions": args.transitions})
        raw, gym_, col = [], [], []
        for _ in range(args.repeats):  # interleaved, so machine noise hits all three alike
            raw.append(raw_rate(domain, p.env, 20_000))
            gym_.append(gym_rate(domain, p.env, 5_000))
            col.append(collect_random(domain, p.env, rcfg)[1]["transitions_per_s"])
        row = {"domain": domain, "raw_control_steps_per_s": float(np.median(raw)),
               "gymnasium_steps_per_s": float(np.median(gym_)), "collect_transitions_per_s": float(np.median(col)),
               "threads": p.random.threads}
        row["collect_over_raw"] = row["collect_transitions_per_s"] / row["raw_control_steps_per_s"]
        row["gymnasium_over_raw"] = row["gymnasium_steps_per_s"] / row["raw_control_steps_per_s"]
        rows.append(row)
        print(f"{domain}: raw {row['raw_control_steps_per_s']:.0f}/s, gymnasium {row['gymnasium_steps_per_s']:.0f}/s "
              f"({row['gymnasium_over_raw']:.2f}), collect {row['collect_transitions_per_s']:.0f}/s "
              f"(ratio {row['collect_over_raw']:.2f}, bar 0.8)")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    doc = {"machine": platform.processor() or platform.machine(), "cpus": os.cpu_count(),
           "mujoco": mujoco.__version__, "rows": rows}
    out.write_text(json.dumps(doc, indent=2) + "\n")


if __name__ == "__main__":
    main()
