"""Behaviour cloning: minimise E||a - pi(y)||^2 (paper §III-A), 90/10 split, minimum-validation checkpoint.

A policy is a set of members, each reading its own named state columns and writing its own named
action columns of domain Y:

* LfDT and its ablations: one member, all of y -> (a^R1, a^R2), from translated demonstrations;
* BC without translation (paper §IV-C): pi^R1(x^R1, x^O) from R1H's raw demonstrations with the
  recorded robot action, pi^R2(x^R2, x^O) from HR2's, run side by side in Y.

Inputs and actions are z-scored with the statistics of each member's own training data (std floors 1e-2 and
1e-4); the loss is measured in normalised action units.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import torch
from torch import nn

from lfdt import layout, methods
from lfdt.config import BCConfig
from lfdt.layout import TaskLayout
from lfdt.nets import Normalizer, check_finite, load_state, mlp, read_config, save_state


class BCMember(nn.Module):
    """One cloned policy: named state columns in, named action columns out."""

    def __init__(self, in_columns: list[str], out_columns: list[str], hidden: list[int]):
        super().__init__()
        self.in_columns = list(in_columns)
        self.out_columns = list(out_columns)
        self.norm = Normalizer(np.zeros(len(in_columns)), np.ones(len(in_columns)))
        self.act_norm = Normalizer(np.zeros(len(out_columns)), np.ones(len(out_columns)))
        self.net = mlp(len(in_columns), len(out_columns), hidden)

    def forward(self, s: torch.Tensor) -> torch.Tensor:
        """The action (raw units) for raw states."""
        return self.act_norm.inverse(self.net(self.norm(s)))

    def loss(self, s: torch.Tensor, a: torch.Tensor, input_noise: float = 0.0,
             generator: torch.Generator | None = None) -> torch.Tensor:
        """Mean squared error in normalised action units (every action dimension weighs alike); ``input_noise``
        perturbs the normalised inputs (training only)."""
        z = self.norm(s)
        if input_noise > 0:
            # drawn on the CPU, so a seed gives the same noise on every device
            z = z + input_noise * torch.randn(z.shape, generator=generator).to(z.device)
        return ((self.net(z) - self.act_norm(a)) ** 2).mean()


@dataclass
class BCTask:
    """What one member learns from: its columns and a DataFrame of transitions (state.*, action.*)."""

    name: str
    in_columns: list[str]
    out_columns: list[str]
    frame: pd.DataFrame


def tasks_for(method: str, translated: pd.DataFrame | None = None,
              raw_demos: dict[str, pd.DataFrame] | None = None, *, tl: TaskLayout) -> list[BCTask]:
    """The members a method trains, with their data."""
    if methods.get(method).data == "raw":
        out = []
        for pairing, df in (raw_demos or {}).items():
            robot = layout.robot_arm(pairing)
            out.append(BCTask(f"pi_{robot}", tl.arm_columns(robot) + tl.object_cols, tl.arm_action_columns(robot), df))
        if sorted(t.name for t in out) != ["pi_r1", "pi_r2"]:
            raise ValueError(f"{method} needs the raw demonstrations of both pairings")
        return out
    if translated is None:
        raise ValueError(f"{method} needs translated demonstrations")
    return [BCTask("pi", tl.state_columns("Y"), tl.action_columns("Y"), translated)]


def _split(episodes: np.ndarray, val_fraction: float, rng: np.random.Generator) -> np.ndarray:
    eps = np.unique(episodes)
    n_val = max(1, int(round(val_fraction * len(eps)))) if len(eps) > 1 else 0
    val_eps = rng.choice(eps, size=n_val, replace=False) if n_val else np.array([], dtype=eps.dtype)
    return np.isin(episodes, val_eps)


def train_member(task: BCTask, cfg: BCConfig, seed: int, log: Callable[[dict, int], None] | None = None,
                 progress=None, device: str | torch.device = "cpu") -> tuple[BCMember, dict]:
    """Fit one member on ``device``; keep the parameters of the lowest validation loss. The member comes back on
    the CPU."""
    torch.manual_seed(seed)
    torch.set_num_threads(cfg.torch_threads)
    rng = np.random.default_rng(seed)
    gen = torch.Generator().manual_seed(seed)
    s = task.frame[[layout.STATE_PREFIX + c for c in task.in_columns]].to_numpy(np.float32, copy=True)
    a = task.frame[[layout.ACTION_PREFIX + c for c in task.out_columns]].to_numpy(np.float32, copy=True)
    val = _split(task.frame.episode_index.to_numpy(), cfg.val_fraction, rng)
    member = BCMember(task.in_columns, task.out_columns, list(cfg.hidden))
    member.norm.load_state_dict(Normalizer.fit(s[~val], 1e-2).state_dict())
    # actions can be torques in [-1, 1] or displacements of a few millimetres: both are learnt at unit scale
    member.act_norm.load_state_dict(Normalizer.fit(a[~val], 1e-4).state_dict())
    member.to(device)
    s_t, a_t = torch.from_numpy(s).to(device), torch.from_numpy(a).to(device)
    # indices are drawn on the CPU (one generator for every device) and moved with the batch
    tr_idx = torch.from_numpy(np.flatnonzero(~val))
    va_idx = torch.from_numpy(np.flatnonzero(val)).to(device)
    opt = torch.optim.Adam(member.parameters(), lr=cfg.learning_rate)
    best, best_state, best_it = float("inf"), None, 0
    curve, running = [], 0.0
    t0 = time.perf_counter()
    for it in range(1, cfg.iterations + 1):
        idx = tr_idx[torch.randint(0, len(tr_idx), (cfg.batch_size,), generator=gen)].to(device)
        loss = member.loss(s_t[idx], a_t[idx], cfg.input_noise, gen)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        running += check_finite(loss.item(), "the BC loss", it)
        if progress is not None:
            progress.update(1)
        if it % cfg.eval_every == 0 or it == cfg.iterations:
            n = cfg.eval_every if it % cfg.eval_every == 0 else it % cfg.eval_every
            with torch.no_grad():
                sel = va_idx if len(va_idx) else tr_idx.to(device)
                v = float(member.loss(s_t[sel], a_t[sel]))
            point = {f"{task.name}/train_loss": running / n, f"{task.name}/val_loss": v}
            running = 0.0
            curve.append({"iteration": it, **point})
            if v < best:
                best, best_it = v, it
                best_state = {k: t.clone() for k, t in member.state_dict().items()}
            if log:
                log(point, it)
    member.load_state_dict(best_state)
    wall = time.perf_counter() - t0
    stats = {"best_val_loss": best, "best_iteration": best_it, "train_samples": int((~val).sum()),
             "val_samples": int(val.sum()), "wall_time_s": wall, "iterations_per_s": cfg.iterations / wall,
             "curve": curve}
    return member.cpu().eval(), stats


class BCPolicy:
    """A trained policy for domain Y: its members' actions, put in Y's action order, optionally clipped."""

    def __init__(self, members: list[BCMember], tl: TaskLayout,
                 action_bounds: tuple[float, float] | None = (-1.0, 1.0)):
        self.members = members
        self.action_bounds = action_bounds
        y_cols = tl.state_columns("Y")
        a_cols = tl.action_columns("Y")
        self._n_actions = len(a_cols)
        self._in = [np.array([y_cols.index(c) for c in m.in_columns]) for m in members]
        self._out = [np.array([a_cols.index(c) for c in m.out_columns]) for m in members]
        covered = np.concatenate(self._out)
        if sorted(covered.tolist()) != list(range(len(a_cols))):
            raise ValueError("the policy's members do not cover every action of domain Y exactly once")

    def __call__(self, y: np.ndarray) -> np.ndarray:
        act = np.zeros(self._n_actions)
        with torch.no_grad():
            for m, i, o in zip(self.members, self._in, self._out):
                act[o] = m(torch.as_tensor(y[i], dtype=torch.float32)[None])[0].numpy()
        return act if self.action_bounds is None else np.clip(act, *self.action_bounds)

    def save(self, out_dir: Path, config: dict) -> None:
        """One state dict per member (``<name>.pt``) with a JSON config beside it."""
        for m, name in zip(self.members, config["members"]):
            save_state(m, Path(out_dir) / f"{name}.pt",
                       {**config, "member": name, "in_columns": m.in_columns, "out_columns": m.out_columns})

    @classmethod
    def load(cls, model_dir: Path, tl: TaskLayout,
             action_bounds: tuple[float, float] | None = (-1.0, 1.0)) -> tuple[BCPolicy, dict]:
        """Load every member of a saved policy (``weights_only=True``)."""
        members, cfg = [], None
        for pt in sorted(Path(model_dir).glob("*.pt")):
            cfg = read_config(pt)
            m = BCMember(cfg["in_columns"], cfg["out_columns"], cfg["bc"]["hidden"])
            members.append(load_state(m, pt))
        if not members:
            raise FileNotFoundError(f"no policy (*.pt) in {model_dir}")
        return cls(members, tl, action_bounds), cfg
