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
from lfdt.nets import ModelFileError, Normalizer, StackedMLP, check_finite, load_state, read_config, save_state
from lfdt.optim import Adam


class BCMember(nn.Module):
    """Cloned policies of the same columns, one per seed, as one stack (``n`` = 1: one policy): named state columns
    in, named action columns out. Inputs and actions are z-scored with each member's own statistics."""

    def __init__(self, in_columns: list[str], out_columns: list[str], hidden: list[int], n: int = 1,
                 generators: list[torch.Generator] | None = None, init: bool = True):
        super().__init__()
        self.in_columns = list(in_columns)
        self.out_columns = list(out_columns)
        self.hidden = list(hidden)
        self.n = n
        n_in, n_out = len(in_columns), len(out_columns)
        self.norm = Normalizer(np.zeros((n, 1, n_in)), np.ones((n, 1, n_in)))
        self.act_norm = Normalizer(np.zeros((n, 1, n_out)), np.ones((n, 1, n_out)))
        self.net = StackedMLP(n, n_in, n_out, hidden, generators=generators, init=init)

    def forward(self, s: torch.Tensor) -> torch.Tensor:
        """The actions (raw units) for raw states, ``(n, batch, in)`` -> ``(n, batch, out)``; a policy of one also
        takes ``(batch, in)``."""
        if s.dim() == 2:
            if self.n != 1:
                raise ValueError(f"a stack of {self.n} policies needs states of shape (n, batch, in)")
            return self.forward(s[None])[0]
        return self.act_norm.inverse(self.net(self.norm(s)))

    def loss(self, s: torch.Tensor, a: torch.Tensor, input_noise: float = 0.0,
             generators: list[torch.Generator] | None = None) -> torch.Tensor:
        """Mean squared error per member, ``(n,)``, in normalised action units (every action dimension weighs
        alike); ``input_noise`` perturbs the normalised inputs (training only), drawn from each member's generator."""
        z = self.norm(s)
        if input_noise > 0:
            # drawn on the CPU, so a seed gives the same noise on every device
            noise = torch.stack([torch.randn(z.shape[1:], generator=g) for g in generators])
            z = z + input_noise * noise.to(z.device)
        return ((self.net(z) - self.act_norm(a)) ** 2).mean(dim=(1, 2))

    def member(self, k: int) -> BCMember:
        """Member k as a policy of its own (weights copied)."""
        one = BCMember(self.in_columns, self.out_columns, self.hidden, init=False).to(self.norm.mean.device)
        one.load_state_dict({name: t[k:k + 1].detach().clone() for name, t in self.state_dict().items()})
        return one.train(self.training)


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


def recovery_augment(frame: pd.DataFrame, dyn, tl: TaskLayout, copies: int, noise: float, seed: int,
                     action_bounds: tuple[float, float] | None = (-1.0, 1.0)) -> pd.DataFrame:
    """``frame`` (transitions of domain Y) and ``copies`` more copies of it whose states are perturbed by Gaussian
    noise of ``noise`` (Y's normalised units) and whose actions are F^-1(perturbed state, the demonstration's next
    state): the action that takes the perturbed state back onto the demonstration (``bc.recovery_copies``). Copies
    keep their episode index, so a validation split by episode keeps a transition and its copies together."""
    if copies == 0:
        return frame
    s_cols = [layout.STATE_PREFIX + c for c in tl.state_columns("Y")]
    s2_cols = [layout.NEXT_STATE_PREFIX + c for c in tl.state_columns("Y")]
    a_cols = [layout.ACTION_PREFIX + c for c in tl.action_columns("Y")]
    gen = torch.Generator().manual_seed(seed)
    parts = [frame]
    with torch.no_grad():
        y_n = dyn.y_norm(torch.from_numpy(frame[s_cols].to_numpy(np.float32, copy=True)))
        y2_n = dyn.y_norm(torch.from_numpy(frame[s2_cols].to_numpy(np.float32, copy=True)))
        for _ in range(copies):
            yp_n = y_n + noise * torch.randn(y_n.shape, generator=gen)
            a = dyn.inverse_model(yp_n, y2_n)
            if action_bounds is not None:
                a = torch.clamp(a, *action_bounds)
            copy = frame.copy()
            copy[s_cols] = dyn.y_norm.inverse(yp_n).numpy()
            copy[a_cols] = a.numpy()
            parts.append(copy)
    return pd.concat(parts, ignore_index=True)


def _split(episodes: np.ndarray, val_fraction: float, rng: np.random.Generator) -> np.ndarray:
    eps = np.unique(episodes)
    # at least one validation episode, and at least one left to train on (a high fraction of few episodes)
    n_val = min(max(1, int(round(val_fraction * len(eps)))), len(eps) - 1) if len(eps) > 1 else 0
    val_eps = rng.choice(eps, size=n_val, replace=False) if n_val else np.array([], dtype=eps.dtype)
    return np.isin(episodes, val_eps)


def train_members(tasks: list[BCTask], cfg: BCConfig, seeds: list[int],
                  logs: list[Callable[[dict, int], None] | None] | None = None, progress=None,
                  device: str | torch.device = "cpu") -> tuple[list[BCMember], list[dict]]:
    """Fit one member per (task, seed) as one stack on ``device``: the same columns, each its own data, split,
    initialisation, minibatches and input noise; each keeps its parameters of lowest validation loss. A member's
    result is the same bits whether it trains alone or in any stack. The members come back on the CPU, each a policy
    of one."""
    if len(tasks) != len(seeds) or not tasks:
        raise ValueError(f"train_members: {len(tasks)} tasks for {len(seeds)} seeds")
    first = tasks[0]
    if any((t.in_columns, t.out_columns) != (first.in_columns, first.out_columns) for t in tasks):
        raise ValueError("train_members stacks members of the same columns only")
    torch.set_num_threads(cfg.torch_threads)
    n = len(tasks)
    gens = [torch.Generator().manual_seed(s) for s in seeds]
    member = BCMember(first.in_columns, first.out_columns, list(cfg.hidden), n=n, generators=gens)
    data_s, data_a, tr_idx, va_idx = [], [], [], []
    for k, (task, seed) in enumerate(zip(tasks, seeds)):
        s = task.frame[[layout.STATE_PREFIX + c for c in task.in_columns]].to_numpy(np.float32, copy=True)
        a = task.frame[[layout.ACTION_PREFIX + c for c in task.out_columns]].to_numpy(np.float32, copy=True)
        val = _split(task.frame.episode_index.to_numpy(), cfg.val_fraction, np.random.default_rng(seed))
        with torch.no_grad():
            member.norm.mean[k, 0] = Normalizer.fit(s[~val], 1e-2).mean
            member.norm.std[k, 0] = Normalizer.fit(s[~val], 1e-2).std
            # actions can be torques in [-1, 1] or displacements of a few millimetres: both are learnt at unit scale
            member.act_norm.mean[k, 0] = Normalizer.fit(a[~val], 1e-4).mean
            member.act_norm.std[k, 0] = Normalizer.fit(a[~val], 1e-4).std
        data_s.append(torch.from_numpy(s).to(device))
        data_a.append(torch.from_numpy(a).to(device))
        # indices are drawn on the CPU (one generator for every device) and moved with the batch
        tr_idx.append(torch.from_numpy(np.flatnonzero(~val)))
        va_idx.append(torch.from_numpy(np.flatnonzero(val)).to(device))
    member.to(device)
    opt = Adam(member.parameters(), lr=cfg.learning_rate)
    best: list[tuple[float, dict | None, int]] = [(float("inf"), None, 0)] * n
    curves: list[list[dict]] = [[] for _ in range(n)]
    running = np.zeros(n)
    name = first.name
    logs = logs or [None] * n
    t0 = time.perf_counter()
    for it in range(1, cfg.iterations + 1):
        sb, ab = [], []
        for k in range(n):
            idx = tr_idx[k][torch.randint(0, len(tr_idx[k]), (cfg.batch_size,), generator=gens[k])].to(device)
            sb.append(data_s[k][idx])
            ab.append(data_a[k][idx])
        loss = member.loss(torch.stack(sb), torch.stack(ab), cfg.input_noise, gens)
        opt.zero_grad(set_to_none=True)
        loss.sum().backward()
        opt.step()
        values = loss.detach().cpu().numpy()
        for k in range(n):
            check_finite(float(values[k]), "the BC loss", it)
        running += values
        if progress is not None:
            progress.update(n)
        if it % cfg.eval_every == 0 or it == cfg.iterations:
            cnt = cfg.eval_every if it % cfg.eval_every == 0 else it % cfg.eval_every
            for k in range(n):
                one = member.member(k)
                with torch.no_grad():
                    sel = va_idx[k] if len(va_idx[k]) else tr_idx[k].to(device)
                    v = float(one.loss(data_s[k][sel][None], data_a[k][sel][None])[0])
                point = {f"{name}/train_loss": float(running[k]) / cnt, f"{name}/val_loss": v}
                curves[k].append({"iteration": it, **point})
                if v < best[k][0]:
                    best[k] = (v, one.state_dict(), it)
                if logs[k]:
                    logs[k](point, it)
            running[:] = 0.0
    wall = time.perf_counter() - t0
    out, stats = [], []
    for k in range(n):
        one = member.member(k)
        one.load_state_dict(best[k][1])
        out.append(one.cpu().eval())
        stats.append({"best_val_loss": best[k][0], "best_iteration": best[k][2],
                      "train_samples": len(tr_idx[k]), "val_samples": len(va_idx[k]), "wall_time_s": wall,
                      "iterations_per_s": cfg.iterations / wall, "stack_size": n, "curve": curves[k]})
    return out, stats


def train_member(task: BCTask, cfg: BCConfig, seed: int, log: Callable[[dict, int], None] | None = None,
                 progress=None, device: str | torch.device = "cpu") -> tuple[BCMember, dict]:
    """Fit one member (:func:`train_members` with one seed); keep the parameters of the lowest validation loss. The
    member comes back on the CPU."""
    members, stats = train_members([task], cfg, [seed], [log], progress, device)
    return members[0], stats[0]


class BCPolicy:
    """A trained policy for domain Y: its members' actions, put in Y's action order, optionally clipped."""

    def __init__(self, members: list[BCMember], tl: TaskLayout,
                 action_bounds: tuple[float, float] | None = (-1.0, 1.0)):
        self.members = members
        self.action_bounds = action_bounds
        y_cols = tl.state_columns("Y")
        a_cols = tl.action_columns("Y")
        self._n_actions = len(a_cols)
        unknown = [c for m in members for c in m.in_columns if c not in y_cols] + \
            [c for m in members for c in m.out_columns if c not in a_cols]
        if unknown:
            shown = ", ".join(unknown[:4]) + (", ..." if len(unknown) > 4 else "")
            raise ValueError(f"the policy reads or writes columns that domain Y of this task does not have "
                             f"({shown}): a policy of another task?")
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
            try:
                m = BCMember(cfg["in_columns"], cfg["out_columns"], cfg["bc"]["hidden"], init=False)
            except (KeyError, TypeError) as err:
                raise ModelFileError(f"{pt.with_suffix('.json')} is not a BC policy's config (no {err})") from None
            members.append(load_state(m, pt))
        if not members:
            raise ModelFileError(f"no policy (*.pt) in {model_dir}")
        try:
            return cls(members, tl, action_bounds), cfg
        except ValueError as err:
            raise ModelFileError(f"{model_dir}: {err}") from None


class StackedPolicies:
    """Several saved policies of one method (one per seed) acting as one: observations ``(policies, batch, obs)`` to
    actions ``(policies, batch, act)``, each member a stack over the policies (one GEMM per policy and layer), so a
    policy acts the same bits here as alone on the same batch."""

    def __init__(self, policies: list[BCPolicy]):
        if not policies:
            raise ValueError("StackedPolicies needs at least one policy")
        first = policies[0]
        self.action_bounds = first.action_bounds
        self._n_actions, self._in, self._out = first._n_actions, first._in, first._out
        self.members = []
        for j, m in enumerate(first.members):
            ms = [p.members[j] for p in policies]
            if any((x.in_columns, x.out_columns, x.hidden) != (m.in_columns, m.out_columns, m.hidden) for x in ms):
                raise ValueError("StackedPolicies stacks policies of the same members and shapes only")
            stack = BCMember(m.in_columns, m.out_columns, m.hidden, n=len(ms), init=False)
            stack.load_state_dict({k: torch.cat([x.state_dict()[k] for x in ms]) for k in m.state_dict()})
            self.members.append(stack.eval())

    def __call__(self, y: np.ndarray) -> np.ndarray:
        act = np.zeros((*y.shape[:2], self._n_actions))
        with torch.no_grad():
            for m, i, o in zip(self.members, self._in, self._out):
                act[..., o] = m(torch.as_tensor(y[..., i], dtype=torch.float32)).numpy()
        return act if self.action_bounds is None else np.clip(act, *self.action_bounds)
