"""What the numeric pin costs: the same workloads with the code paths pinned and with ``LFDT_NUMERICS=native``.

Each workload runs in a fresh process (the mode is fixed when a process starts), the two modes alternating,
``--repeats`` times; the ratio is the median pinned throughput over the median native throughput (1 = free, 0.5 =
twice as slow):

* translator: a stack of 5 translators (the default config, one worker's share of ten seeds), seed-iterations/s;
* bc: a stack of 5 BC policies, seed-iterations/s;
* sac: stable-baselines3 SAC gradient steps of the default expert (2 environments, 256 x 2), steps/s;
* dynamics: F and F^-1 of the default config on one core, iterations/s.

Writes benchmarks/results/pin_cost.json.
"""

import lfdt.numerics  # noqa: F401

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

from lfdt import numerics

WORKLOADS = ("translator", "bc", "sac", "dynamics")


def work(name: str) -> float:
    import numpy as np
    import torch

    sys.path.insert(0, str(Path(__file__).parent))
    torch.set_num_threads(1)
    if name == "translator":
        from stack_throughput import translator_rate

        return translator_rate(5, True, 100)
    if name == "bc":
        from stack_throughput import bc_rate

        return bc_rate(5, True, 1000)
    if name == "sac":
        from lfdt.config import DemosConfig, EnvConfig, ExpertsConfig
        from lfdt.tasks.box_push import experts

        cfg = ExpertsConfig(learning_starts=256, n_envs=2, buffer_size=5000)
        venv = experts.make_vec_env("R1H", EnvConfig(), DemosConfig(), cfg.n_envs, 0)
        model = experts.build_sac(venv, cfg)
        model.learn(cfg.learning_starts, progress_bar=False)
        t0 = time.perf_counter()
        steps = 600
        model.learn(steps, reset_num_timesteps=False, progress_bar=False)
        return steps / cfg.n_envs / (time.perf_counter() - t0)
    if name == "dynamics":
        from lfdt.config import DynamicsConfig
        from lfdt.dynamics import RandomY, fit_dynamics

        rng = np.random.default_rng(0)
        n = 20_000
        d = RandomY(rng.normal(size=(n, 19)).astype(np.float32), rng.uniform(-1, 1, (n, 6)).astype(np.float32),
                    rng.normal(size=(n, 19)).astype(np.float32), np.arange(n) // 100, [f"s{i}" for i in range(19)],
                    [f"a{i}" for i in range(6)])
        cfg = DynamicsConfig(iterations=300, eval_every=10 ** 6)
        t0 = time.perf_counter()
        fit_dynamics(d, cfg)
        return cfg.iterations / (time.perf_counter() - t0)
    raise ValueError(name)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--only", nargs="*", choices=WORKLOADS)
    ap.add_argument("--worker", choices=WORKLOADS, help=argparse.SUPPRESS)
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/pin_cost.json"))
    args = ap.parse_args()
    if args.worker:
        print(json.dumps({"rate": work(args.worker)}))
        return
    base = {k: v for k, v in os.environ.items() if k not in numerics.PINNED_ENV and k != numerics.SWITCH}
    rates: dict[str, dict[str, list[float]]] = {}
    for _ in range(args.repeats):
        for name in args.only or WORKLOADS:
            for mode in ("pinned", "native"):
                r = subprocess.run([sys.executable, __file__, "--worker", name], capture_output=True, text=True,
                                   env={**base, numerics.SWITCH: mode}, check=True)
                rate = json.loads(r.stdout.strip().splitlines()[-1])["rate"]
                rates.setdefault(name, {}).setdefault(mode, []).append(rate)
                print(f"{name} {mode}: {rate:.1f}/s", flush=True)
    out = {"cpu_model": numerics.cpu_model(), "cpu_isa": numerics.isa(), "date": time.strftime("%Y-%m-%d"),
           "repeats": args.repeats}
    for name, r in rates.items():
        med = {k: statistics.median(v) for k, v in r.items()}
        out[name] = {"per_s": med, "ratio_pinned_over_native": med["pinned"] / med["native"]}
        print(f"{name}: pinned {med['pinned']:.1f}/s, native {med['native']:.1f}/s, ratio "
              f"{med['pinned'] / med['native']:.2f}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
