"""Translator and BC training speed as a ratio to a bare torch loop over the same networks and batch size.

ours:  lfdt.translation.training.train_translator / lfdt.bc.train_member (sampling, losses, diagnostics, checkpoint
       selection included), iterations per second.
bare:  a minimal loop doing the same forward/backward/Adam steps on pre-drawn random tensors of the same shapes
       (G, D and the frozen F, F^-1 for the translator; the policy MLP for BC), nothing else.

Both are measured in one run, alternately, and the medians compared. Bar (issue 3): ours / bare >= 0.7.
Writes benchmarks/results/training_throughput.json.
"""

from __future__ import annotations

import lfdt.numerics  # noqa: F401  (first: pins the numeric code paths before numpy, torch or mujoco load)

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np
import pandas as pd
import torch
import torch.nn.functional as nnf

from lfdt import bc, layout
from lfdt.box_push_jobs.translator import box_push_kinematics
from lfdt.config import BCConfig, EnvConfig, TranslatorConfig
from lfdt.dynamics import DynamicsModels
from lfdt.nets import mlp
from lfdt.tasks.box_push import columns as box_columns
from lfdt.translation.training import train_translator
from lfdt.translation.transitions import Transitions


def fake_transitions(n: int, dim: int, rng: np.random.Generator) -> Transitions:
    x = rng.normal(size=(n, dim)).astype(np.float32)
    return Transitions(x=x, x2=x + 0.01, episode=np.arange(n) // 20, frame=np.arange(n) % 20, x_prev=x)


def ours_translator(iters: int, cfg: TranslatorConfig, dyn: DynamicsModels, rng) -> float:
    demos = {p: fake_transitions(2_000, 21, rng) for p in layout.PAIRINGS}
    rand = {p: fake_transitions(20_000, 21, rng) for p in layout.PAIRINGS}
    y = rng.normal(size=(20_000, 19)).astype(np.float32)
    _, st = train_translator(demos, rand, y, dyn, cfg.model_copy(update={"iterations": iters}), seed=0,
                             kinematics=box_push_kinematics(EnvConfig()), tl=box_columns.BOX_PUSH)
    return st["iterations_per_s"]


def bare_translator(iters: int, cfg: TranslatorConfig, dyn: DynamicsModels) -> float:
    g = mlp(23, 19, list(cfg.hidden))
    d = mlp(19, 1, list(cfg.hidden))
    opt_g = torch.optim.Adam(g.parameters(), lr=cfg.learning_rate)
    opt_d = torch.optim.Adam(d.parameters(), lr=cfg.learning_rate)
    b = cfg.batch_size
    x, x2, y = torch.randn(b, 23), torch.randn(b, 23), torch.randn(b, 19)
    x0 = torch.randn(b, 23)
    t0 = time.perf_counter()
    for _ in range(iters):
        # one pass of G over (x_prev, x, x2), as the translator with Y's kinematics does
        _, yh, yh2 = g(torch.cat([x0, x, x2])).split(b)
        dr, df = d(y), d(yh.detach())
        ld = nnf.binary_cross_entropy_with_logits(dr, torch.ones_like(dr)) + \
            nnf.binary_cross_entropy_with_logits(df, torch.zeros_like(df))
        opt_d.zero_grad()
        ld.backward()
        opt_d.step()
        fake = d(yh)
        ladv = nnf.binary_cross_entropy_with_logits(fake, torch.ones_like(fake))
        ldyn = ((dyn.forward_model(yh, dyn.inverse_model(yh, yh2)) - yh2) ** 2).mean()
        lid = ((yh[:, :8] - x[:, :8]) ** 2).mean()
        loss = ladv + 10 * ldyn + 10 * lid
        opt_g.zero_grad()
        loss.backward()
        opt_g.step()
    return iters / (time.perf_counter() - t0)


def ours_bc(iters: int, cfg: BCConfig, rng) -> float:
    n = 9_000
    df = pd.DataFrame(rng.normal(size=(n, 25)).astype(np.float32),
                      columns=[layout.STATE_PREFIX + c for c in box_columns.state_columns("Y")] +
                      [layout.ACTION_PREFIX + c for c in box_columns.action_columns("Y")])
    df["episode_index"] = np.arange(n) // 25
    task = bc.tasks_for("lfdt", translated=df, tl=box_columns.BOX_PUSH)[0]
    _, st = bc.train_member(task, cfg.model_copy(update={"iterations": iters}), seed=0)
    return st["iterations_per_s"]


def bare_bc(iters: int, cfg: BCConfig) -> float:
    net = mlp(19, 6, list(cfg.hidden))
    opt = torch.optim.Adam(net.parameters(), lr=cfg.learning_rate)
    s, a = torch.randn(cfg.batch_size, 19), torch.randn(cfg.batch_size, 6)
    t0 = time.perf_counter()
    for _ in range(iters):
        loss = ((net(s) - a) ** 2).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
    return iters / (time.perf_counter() - t0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--iterations", type=int, default=2_000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", default="benchmarks/results/training_throughput.json")
    args = ap.parse_args()
    torch.set_num_threads(1)
    from lfdt.config import load_params

    p = load_params("params.yaml")
    rng = np.random.default_rng(0)
    dyn = DynamicsModels(19, 6, list(p.dynamics.hidden)).eval()
    for prm in dyn.parameters():
        prm.requires_grad_(False)
    rates = {"translator_ours": [], "translator_bare": [], "bc_ours": [], "bc_bare": []}
    for _ in range(args.repeats):
        rates["translator_ours"].append(ours_translator(args.iterations, p.translator, dyn, rng))
        rates["translator_bare"].append(bare_translator(args.iterations, p.translator, dyn))
        rates["bc_ours"].append(ours_bc(args.iterations * 2, p.bc, rng))
        rates["bc_bare"].append(bare_bc(args.iterations * 2, p.bc))
    med = {k: float(np.median(v)) for k, v in rates.items()}
    out = {"machine": platform.machine(), "torch": torch.__version__, "threads": 1, "median_it_per_s": med,
           "translator_ratio": med["translator_ours"] / med["translator_bare"],
           "bc_ratio": med["bc_ours"] / med["bc_bare"], "all": rates}
    print(f"translator: ours {med['translator_ours']:.0f} it/s, bare {med['translator_bare']:.0f} it/s, "
          f"ratio {out['translator_ratio']:.2f} (bar 0.7)")
    print(f"BC: ours {med['bc_ours']:.0f} it/s, bare {med['bc_bare']:.0f} it/s, ratio {out['bc_ratio']:.2f} (bar 0.7)")
    path = Path(args.out)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
