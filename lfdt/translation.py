"""Domain translation X -> Y (paper §III-C): generator G, discriminator D, eqs. 1-6.

G maps a state of domain X, in the canonical order ``[x^Ri, x^H, x^O]`` of its pairing plus a
one-hot of the pairing, to a normalised state of domain Y ``[y^R1, y^R2, y^O]``. D tells real
normalised Y states (from Y's random motion) from G's outputs. The generator's loss is

    lambda_adv * L_adv + lambda_dyn * L_dyn + lambda_id * L_id

with L_dyn = ||F(y_hat_t, F^-1(y_hat_t, y_hat_t+1)) - y_hat_t+1||^2 through the frozen dynamics
models and L_id = ||y_hat^Ri - x^Ri||^2 on the robot that is really there. The ablations are the
same code with a weight at zero (:mod:`lfdt.methods`).

Normalisation: x^Ri and x^O use Y's statistics of the same columns (so L_id compares like with
like); x^H uses the statistics of the human columns in that pairing's X random data.

Batches: half demonstration transitions, half X random-motion transitions, each half split
evenly between the two pairings; D sees as many real Y states. The human's recorded actions are
never read.
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd
import pyarrow as pa
import torch
import torch.nn.functional as nnf
from torch import nn

from lfdt import data, layout, methods
from lfdt.config import TranslatorConfig
from lfdt.dynamics import DynamicsModels
from lfdt.layout import TaskLayout
from lfdt.nets import Normalizer, StackedMLP, check_finite, sin_cos, softplus
from lfdt.optim import Adam

PAIRING_INDEX = {p: i for i, p in enumerate(layout.PAIRINGS)}


def method_config(method: str, cfg: TranslatorConfig) -> TranslatorConfig:
    """The translator config of a translator method (:mod:`lfdt.methods`; an ablation sets one weight to zero)."""
    m = methods.get(method)
    if not m.trains_translator:
        raise ValueError(f"{method!r} trains no translator; translator methods: {methods.translator_methods()}")
    return cfg.model_copy(update=m.overrides)


def canonical_x_columns(pairing: str, tl: TaskLayout) -> list[str]:
    """G's input columns of a pairing: the robot that is there, the human stand-in, the object."""
    return tl.canonical_x_columns(pairing)


@dataclass(frozen=True)
class ArmKinematics:
    """One planar serial arm of Y (angle 0 along +y): where its columns sit in a Y state, its links and base."""

    q: list[int]
    """Y-state indices of its joint angles."""
    dq: list[int]
    """Y-state indices of its joint velocities."""
    ee: list[int]
    """Y-state indices of its end position (x, y)."""
    links: list[float]
    """Link lengths, m."""
    base: list[float]
    """Base position, m."""


@dataclass(frozen=True)
class Kinematics:
    """What the translator may take from Y's known robot model (``translator.kinematics: forward``): an arm's
    end position is the forward kinematics of its joint angles, and its joint velocity the change of its joint
    angles over the last control step (the arms are overdamped: this holds within ~5 % on Y's own data)."""

    arms: list[ArmKinematics]
    dt: float
    """Control step, s."""


def forward_kinematics(q: torch.Tensor, links: torch.Tensor, base: torch.Tensor) -> torch.Tensor:
    """End positions (..., 2) of a planar arm for joint angles q (..., n), differentiable."""
    sin, cos = sin_cos(torch.cumsum(q, dim=-1))
    return torch.stack([base[0] - (links * sin).sum(-1), base[1] + (links * cos).sum(-1)], -1)


@dataclass
class Transitions:
    """Consecutive state pairs of one pairing in canonical X order (raw units)."""

    x: np.ndarray
    x2: np.ndarray
    episode: np.ndarray
    frame: np.ndarray
    a: np.ndarray | None = None
    """The real robot's recorded action (demonstrations; diagnostics only, never trained on)."""
    x_prev: np.ndarray | None = None
    """The state one step before x (x itself at an episode's first frame); None means x."""

    def subset(self, m: np.ndarray) -> Transitions:
        """The transitions selected by a boolean mask or index array."""
        return Transitions(self.x[m], self.x2[m], self.episode[m], self.frame[m],
                           None if self.a is None else self.a[m], None if self.x_prev is None else self.x_prev[m])


def load_x_transitions(path, pairing: str, episodes: list[int] | None = None, *, tl: TaskLayout,
                       with_actions: bool = False, kind: str) -> Transitions:
    """State pairs of an X dataset (``kind`` 'random' or 'demos', checked), canonical column order, optionally some
    episodes only; ``with_actions`` also reads the real robot's recorded action (for diagnostics)."""
    cols = tl.canonical_x_columns(pairing)
    a_cols = [layout.ACTION_PREFIX + c for c in tl.arm_action_columns(layout.robot_arm(pairing))]
    names = ["episode_index", "frame_index"] + [layout.STATE_PREFIX + c for c in cols] + \
        [layout.NEXT_STATE_PREFIX + c for c in cols] + (a_cols if with_actions else [])
    df = data.read_transitions(path, columns=names, kind=kind, domain=pairing, task=tl.name)
    if episodes is not None:
        df = df[df.episode_index.isin(episodes)]
    df = df.sort_values(["episode_index", "frame_index"], kind="stable")
    x = np.array(df[[layout.STATE_PREFIX + c for c in cols]].to_numpy(np.float32))
    episode = df.episode_index.to_numpy()
    first = np.r_[True, episode[1:] != episode[:-1]]
    x_prev = np.where(first[:, None], x, np.roll(x, 1, axis=0))
    return Transitions(
        x=x, x2=np.array(df[[layout.NEXT_STATE_PREFIX + c for c in cols]].to_numpy(np.float32)),
        episode=episode, frame=df.frame_index.to_numpy(),
        a=df[a_cols].to_numpy(np.float32) if with_actions else None, x_prev=x_prev)


def split_held_out(sets: dict[str, Transitions], fraction: float, seed: int
                   ) -> tuple[dict[str, Transitions], dict[str, Transitions] | None]:
    """Split each pairing's demonstrations by whole episodes: (training, held out for checkpoint selection).

    ``fraction`` 0 holds nothing out (returns None); otherwise at least one episode per pairing is held out.
    """
    if fraction <= 0:
        return sets, None
    train, held = {}, {}
    rng = np.random.default_rng([seed, 7])
    for p, t in sets.items():
        eps = np.unique(t.episode)
        if len(eps) < 2:
            raise ValueError(f"{p}: {len(eps)} demonstration(s) cannot be split for translator.holdout_fraction")
        n = max(1, int(round(fraction * len(eps))))
        out = np.isin(t.episode, rng.choice(eps, size=n, replace=False))
        train[p], held[p] = t.subset(~out), t.subset(out)
    return train, held


class Translator(nn.Module):
    """G, D and the X normalisers of both pairings, saved as one state dict.

    G and D are stacks of ``n`` nets (:class:`lfdt.nets.StackedMLP`): the translators of several seeds (or restarts)
    of one configuration train as one model, each member with its own weights, data and random draws; what they
    share (normalisers, skips, Y's kinematics) is data, not learnt. States carry the stack as their first dimension:
    ``(n, batch, columns)``. A saved translator is a stack of one (:meth:`member`)."""

    def __init__(self, hidden: list[int], tl: TaskLayout, slope: float = 0.2,
                 kinematics: Kinematics | None = None, d_cols: list[int] | None = None, hand_offset: bool = False,
                 n: int = 1, generators: list[torch.Generator] | None = None):
        super().__init__()
        x_dim = len(tl.canonical_x_columns("R1H"))
        y_dim = len(tl.state_columns("Y"))
        self.n = n
        self.hidden, self.slope = list(hidden), slope
        self.x_norms = nn.ModuleDict({p: Normalizer(np.zeros(x_dim), np.ones(x_dim)) for p in layout.PAIRINGS})
        self.G = StackedMLP(n, x_dim + len(layout.PAIRINGS), y_dim, hidden, slope, generators)
        # the columns of y D sees (disc_input): all, or the robots' only
        d_cols = list(range(y_dim)) if d_cols is None else d_cols
        self.register_buffer("d_idx", torch.as_tensor(d_cols, dtype=torch.long))
        self.D = StackedMLP(n, len(d_cols), 1, hidden, slope, generators)
        # skip connections (see skip_pairs): y_n[j] += x_n[src[j]] * scale[j] + offset[j] where src[j] >= 0
        n_p = len(layout.PAIRINGS)
        self.register_buffer("skip_src", torch.full((n_p, y_dim), -1, dtype=torch.long))
        self.register_buffer("skip_scale", torch.zeros(n_p, y_dim))
        self.register_buffer("skip_offset", torch.zeros(n_p, y_dim))
        # 1 where G's own output counts, 0 where the state is copied from x (object: "copy")
        self.register_buffer("g_mask", torch.ones(y_dim))
        # Y's robot model (kinematics: "forward"): end columns from the joint angles, velocities from their change
        arms = kinematics.arms if kinematics else []
        n_j = len(arms[0].q) if arms else 0
        self.register_buffer("fk_q", torch.as_tensor([a.q for a in arms], dtype=torch.long).view(len(arms), n_j))
        self.register_buffer("fk_dq", torch.as_tensor([a.dq for a in arms], dtype=torch.long).view(len(arms), n_j))
        self.register_buffer("fk_ee", torch.as_tensor([a.ee for a in arms], dtype=torch.long).view(len(arms), 2))
        self.register_buffer("fk_links", torch.as_tensor([a.links for a in arms], dtype=torch.float32)
                             .view(len(arms), n_j))
        self.register_buffer("fk_base", torch.as_tensor([a.base for a in arms], dtype=torch.float32).view(len(arms), 2))
        self.register_buffer("fk_dt", torch.tensor(kinematics.dt if kinematics else 1.0))
        self.register_buffer("y_mean", torch.zeros(y_dim))
        self.register_buffer("y_std", torch.ones(y_dim))
        # the human's hand -> the missing robot's end, per pairing (for lambda_hand): x index, y index, scale, offset
        self.register_buffer("hand_src", torch.zeros(n_p, 2, dtype=torch.long))
        self.register_buffer("hand_dst", torch.zeros(n_p, 2, dtype=torch.long))
        self.register_buffer("hand_scale", torch.ones(n_p, 2))
        self.register_buffer("hand_offset", torch.zeros(n_p, 2))
        # hand_offset: a constant offset per member and pairing between the hand and the missing robot's end, trained
        # with G (Y's normalised units); only then, so that translators without it have no such parameter
        self.hand_shift = nn.Parameter(torch.zeros(n, n_p, 2)) if hand_offset else None

    def member(self, k: int) -> Translator:
        """Member k as a translator of its own (a stack of one; weights copied, the shared buffers too)."""
        one = Translator.__new__(Translator)
        nn.Module.__init__(one)
        one.n, one.hidden, one.slope = 1, self.hidden, self.slope
        for name, buf in self.named_buffers(recurse=False):
            one.register_buffer(name, buf.clone())
        one.x_norms = copy.deepcopy(self.x_norms)
        one.G, one.D = self.G.member(k), self.D.member(k)
        one.hand_shift = None if self.hand_shift is None else nn.Parameter(self.hand_shift[k:k + 1].detach().clone())
        return one.train(self.training)

    def generator_parameters(self) -> list[nn.Parameter]:
        """What G's optimiser trains: G's weights, and the learnt hand offset where there is one."""
        return [*self.G.parameters(), *([] if self.hand_shift is None else [self.hand_shift])]

    def hand_offset_m(self, tl: TaskLayout, k: int = 0) -> dict[str, float]:
        """Member k's learnt hand offset in metres (the missing robot's end minus the hand), keyed by the missing
        robot's Y column; empty without one."""
        if self.hand_shift is None:
            return {}
        cols = tl.state_columns("Y")
        shift = self.hand_shift[k].detach() * self.y_std[self.hand_dst]
        return {cols[int(j)]: float(shift[i, c]) for i in PAIRING_INDEX.values()
                for c, j in enumerate(self.hand_dst[i])}

    def generate(self, x_n: torch.Tensor, pairing_idx: torch.Tensor,
                 x_prev_n: torch.Tensor | None = None) -> torch.Tensor:
        """y_hat (normalised Y states, ``(n, batch, y)``) from normalised canonical x (``(n, batch, x)``) and the
        pairing index (``(n, batch)``).

        With Y's robot model (``kinematics: forward``) the end columns are the forward kinematics of the joint
        angles, and, given the previous state ``x_prev_n`` (equal to ``x_n`` at an episode's first frame, where
        the arms are at rest), the joint velocities are the change of the joint angles over the control step.
        """
        y = self._raw_generate(x_n, pairing_idx)
        if len(self.fk_q):
            y_prev = None if x_prev_n is None else self._raw_generate(x_prev_n, pairing_idx)
            y = self.apply_kinematics(y, y_prev)
        return y

    def _raw_generate(self, x_n: torch.Tensor, pairing_idx: torch.Tensor) -> torch.Tensor:
        onehot = nnf.one_hot(pairing_idx, len(layout.PAIRINGS)).to(x_n.dtype)
        y = self.G(torch.cat([x_n, onehot], dim=-1)) * self.g_mask
        src = self.skip_src[pairing_idx]
        has = src >= 0
        if bool(has.any()):
            copied = torch.gather(x_n, -1, src.clamp(min=0))
            y = y + torch.where(has, copied * self.skip_scale[pairing_idx] + self.skip_offset[pairing_idx],
                                torch.zeros_like(y))
        return y

    def generate_pair(self, x0: torch.Tensor, x: torch.Tensor, x2: torch.Tensor, pairing_idx: torch.Tensor
                      ) -> tuple[torch.Tensor, torch.Tensor]:
        """(y_hat_t, y_hat_t+1) of transitions (x, x2) whose previous states are x0, in one pass of G."""
        n = x.shape[1]
        if not len(self.fk_q):
            y = self._raw_generate(torch.cat([x, x2], dim=1), pairing_idx.repeat(1, 2))
            return y[:, :n], y[:, n:]
        y = self._raw_generate(torch.cat([x0, x, x2], dim=1), pairing_idx.repeat(1, 3))
        y0, y1, y2 = y[:, :n], y[:, n:2 * n], y[:, 2 * n:]
        return self.apply_kinematics(y1, y0), self.apply_kinematics(y2, y1)

    def apply_kinematics(self, y_n: torch.Tensor, y_prev_n: torch.Tensor | None = None) -> torch.Tensor:
        """Each arm's end columns from its joint angles; its joint velocities from the change since ``y_prev_n``
        (when given). Normalised units in and out, any leading dimensions."""
        qi, dqi, ei = self.fk_q, self.fk_dq, self.fk_ee  # (arms, joints), (arms, joints), (arms, 2)
        lead = y_n.shape[:-1]
        q = y_n[..., qi] * self.y_std[qi] + self.y_mean[qi]  # (..., arms, joints)
        sin, cos = sin_cos(torch.cumsum(q, dim=-1))
        ee = torch.stack([self.fk_base[:, 0] - (self.fk_links * sin).sum(-1),
                          self.fk_base[:, 1] + (self.fk_links * cos).sum(-1)], dim=-1)
        y_n = y_n.clone()
        y_n[..., ei.reshape(-1)] = ((ee - self.y_mean[ei]) / self.y_std[ei]).reshape(*lead, -1)
        if y_prev_n is not None:
            q_prev = y_prev_n[..., qi] * self.y_std[qi] + self.y_mean[qi]
            dq = ((q - q_prev) / self.fk_dt - self.y_mean[dqi]) / self.y_std[dqi]
            y_n[..., dqi.reshape(-1)] = dq.reshape(*lead, -1)
        return y_n

    def disc(self, y: torch.Tensor) -> torch.Tensor:
        """D's logit (``(n, batch, 1)``) that ``y`` (normalised Y states, ``(n, batch, y)``) is real, from the
        columns D sees."""
        return self.D(y.index_select(-1, self.d_idx))

    def translate(self, x: np.ndarray, pairing: str) -> torch.Tensor:
        """Normalised y_hat for the raw canonical states of one episode of a pairing, in time order (no gradient), by
        a translator of one member.

        The first state is the episode's start (the arms at rest)."""
        if self.n != 1:
            raise ValueError(f"translate() needs a translator of one member; this one has {self.n} (use member(k))")
        with torch.no_grad():
            xt = self.x_norms[pairing](torch.as_tensor(x, dtype=torch.float32))[None]
            idx = torch.full(xt.shape[:2], PAIRING_INDEX[pairing], dtype=torch.long)
            return self.generate(xt, idx, torch.cat([xt[:, :1], xt[:, :-1]], dim=1))[0]


def skip_pairs(pairing: str, object_mode: str, hand_skip: bool, tl: TaskLayout) -> list[tuple[str, str]]:
    """(x column, y column) pairs G adds to its output: quantities observed in the same world frame in X and Y.

    object_mode 'correct' or 'copy': the object's pose (the same object, seen alike in both domains);
    hand_skip: the human's hand position -> the end position of the robot that will stand in its place.
    """
    pairs = []
    if object_mode in ("correct", "copy"):
        pairs += [(c, c) for c in tl.object_cols]
    if hand_skip:
        missing = "r2" if layout.robot_arm(pairing) == "r1" else "r1"
        pairs += list(zip(tl.position_cols["h"], tl.position_cols[missing]))
    return pairs


def fit_x_normalizers(translator: Translator, dyn: DynamicsModels, random_x: dict[str, Transitions],
                      std_floor: float, object_mode: str = "translate", hand_skip: bool = False,
                      *, tl: TaskLayout) -> None:
    """Robot and object columns take Y's statistics; the human's come from that pairing's X random data.

    Also sets the skip connections, converting each copied x column from its normalisation to its y column's.
    """
    y_cols = tl.state_columns("Y")
    for pairing, tr in random_x.items():
        cols = tl.canonical_x_columns(pairing)
        own = Normalizer.fit(tr.x, std_floor)
        mean, std = own.mean.clone(), own.std.clone()
        for i, c in enumerate(cols):
            if not c.startswith("h."):
                j = y_cols.index(c)
                mean[i], std[i] = dyn.y_norm.mean[j], dyn.y_norm.std[j]
        translator.x_norms[pairing].mean.copy_(mean)
        translator.x_norms[pairing].std.copy_(std)
        k = PAIRING_INDEX[pairing]
        missing = "r2" if layout.robot_arm(pairing) == "r1" else "r1"
        for n, (xc, yc) in enumerate(zip(tl.position_cols["h"], tl.position_cols[missing])):
            i, j = cols.index(xc), y_cols.index(yc)
            translator.hand_src[k, n], translator.hand_dst[k, n] = i, j
            translator.hand_scale[k, n] = std[i] / dyn.y_norm.std[j]
            translator.hand_offset[k, n] = (mean[i] - dyn.y_norm.mean[j]) / dyn.y_norm.std[j]
        for xc, yc in skip_pairs(pairing, object_mode, hand_skip, tl):
            i, j = cols.index(xc), y_cols.index(yc)
            # x_raw = x_n * std_x + mean_x; y_n = (x_raw - mean_y) / std_y
            translator.skip_src[k, j] = i
            translator.skip_scale[k, j] = std[i] / dyn.y_norm.std[j]
            translator.skip_offset[k, j] = (mean[i] - dyn.y_norm.mean[j]) / dyn.y_norm.std[j]
    if object_mode == "copy":
        for c in tl.object_cols:
            translator.g_mask[y_cols.index(c)] = 0.0


def _gan_losses(kind: str):
    """(D's loss, G's adversarial loss) per member, from logits ``(n, batch, 1)``: shape ``(n,)``.

    'bce' is eq. 1's binary cross-entropy with logits, written as softplus (-log sigmoid(l) = softplus(-l)):
    :func:`lfdt.nets.softplus` gives every element the same code wherever it sits in a stack of members."""
    if kind == "bce":
        def d_loss(real, fake):
            return softplus(-real).mean(dim=(1, 2)) + softplus(fake).mean(dim=(1, 2))

        def g_loss(fake):
            return softplus(-fake).mean(dim=(1, 2))
    else:
        def d_loss(real, fake):
            return ((real - 1) ** 2).mean(dim=(1, 2)) + (fake ** 2).mean(dim=(1, 2))

        def g_loss(fake):
            return ((fake - 1) ** 2).mean(dim=(1, 2))
    return d_loss, g_loss


class _Sampler:
    """Draws the transitions of one member's batches from per-pairing tensors, with the member's generator."""

    def __init__(self, sets: dict[str, Transitions], translator: Translator, gen: torch.Generator,
                 device: str | torch.device = "cpu", cache: dict | None = None):
        self.gen, self.device = gen, device
        self.x, self.x2, self.x0, self.n = {}, {}, {}, {}
        for p, tr in sets.items():
            key = (id(tr), p)
            if cache is not None and key in cache:  # members sharing a data set share its tensors
                self.x[p], self.x2[p], self.x0[p] = cache[key]
            else:
                norm = translator.x_norms[p]
                with torch.no_grad():
                    self.x[p] = norm(torch.as_tensor(tr.x, device=device))
                    self.x2[p] = norm(torch.as_tensor(tr.x2, device=device))
                    self.x0[p] = self.x[p] if tr.x_prev is None else norm(torch.as_tensor(tr.x_prev, device=device))
                if cache is not None:
                    cache[key] = (self.x[p], self.x2[p], self.x0[p])
            self.n[p] = len(tr.x)

    def sample(self, per_pairing: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """(x_prev, x, x2, pairing index) of ``per_pairing`` random transitions of each pairing."""
        x0s, xs, x2s, ps = [], [], [], []
        for p in layout.PAIRINGS:
            # drawn on the CPU, so a seed draws the same batches on every device
            idx = torch.randint(0, self.n[p], (per_pairing,), generator=self.gen).to(self.device)
            x0s.append(self.x0[p][idx])
            xs.append(self.x[p][idx])
            x2s.append(self.x2[p][idx])
            ps.append(torch.full((per_pairing,), PAIRING_INDEX[p], dtype=torch.long, device=self.device))
        return torch.cat(x0s), torch.cat(xs), torch.cat(x2s), torch.cat(ps)


class _Losses:
    """The generator's losses of eq. 6 on one batch per member, reusable for training, selection and diagnostics.

    Inputs carry the members as their first dimension, ``(n, batch, ...)``; every loss comes back per member,
    ``(n,)``."""

    def __init__(self, tr: Translator, dyn: DynamicsModels, cfg: TranslatorConfig, tl: TaskLayout):
        self.tr, self.dyn, self.cfg = tr, dyn, cfg
        y_dim = len(tl.state_columns("Y"))
        dev = dyn.delta_scale.device
        self.robot_mask = torch.zeros(len(layout.PAIRINGS), y_dim, dtype=torch.bool, device=dev)
        for p, i in PAIRING_INDEX.items():
            self.robot_mask[i, tl.robot_y_slice(p)] = True
        self.n_robot = len(tl.arm_cols["r1"])
        self.dyn_scale = dyn.delta_scale if cfg.dyn_scale == "delta" else torch.ones_like(dyn.delta_scale)
        obj = [tl.state_columns("Y").index(c) for c in tl.object_cols]
        self.object_mask = torch.zeros(y_dim, dtype=torch.bool, device=dev)
        self.object_mask[obj] = True
        self.dyn_weight = torch.ones(y_dim, device=dev)
        self.dyn_weight[obj] = cfg.dyn_object_weight

    def __call__(self, x0: torch.Tensor, x: torch.Tensor, x2: torch.Tensor, pidx: torch.Tensor
                 ) -> dict[str, torch.Tensor]:
        """y_hat, y_hat2, the per-column squared dynamics error and the identity loss of a batch
        (``x0``: the states one step before ``x``, used only with Y's robot model)."""
        n, b = x.shape[:2]
        y_hat, y_hat2 = self.tr.generate_pair(x0, x, x2, pidx)
        a_tilde = self.dyn.inverse_model(y_hat, y_hat2)
        y_tilde = self.dyn.forward_model(y_hat, a_tilde)
        dyn_sq = ((y_tilde - y_hat2) / self.dyn_scale) ** 2
        y_robot = y_hat[self.robot_mask[pidx]].view(n, b, self.n_robot)
        l_id = ((y_robot - x[..., :self.n_robot]) ** 2).mean(dim=(1, 2))
        tr = self.tr
        hand = torch.gather(x, -1, tr.hand_src[pidx]) * tr.hand_scale[pidx] + tr.hand_offset[pidx]
        if tr.hand_shift is not None:
            hand = hand + tr.hand_shift[torch.arange(n, device=pidx.device)[:, None], pidx]
        l_hand = ((torch.gather(y_hat, -1, tr.hand_dst[pidx]) - hand) ** 2).mean(dim=(1, 2))
        return {"y_hat": y_hat, "y_hat2": y_hat2, "a_tilde": a_tilde, "dyn_sq": dyn_sq,
                "dyn": (dyn_sq * self.dyn_weight).mean(dim=(1, 2)),
                "id": l_id, "hand": l_hand}

    def dyn_split(self, dyn_sq: torch.Tensor, pidx: torch.Tensor) -> dict[str, float]:
        """L_dyn split by the real robot's columns, the missing robot's and the object's (one member)."""
        dyn_sq, pidx = dyn_sq[0], pidx[0]
        real = self.robot_mask[pidx]
        missing = ~real & ~self.object_mask
        return {"real_robot": float(dyn_sq[real].mean()), "missing_robot": float(dyn_sq[missing].mean()),
                "object": float(dyn_sq[:, self.object_mask].mean())}

    def selection(self, out: dict[str, torch.Tensor]) -> torch.Tensor:
        """The held-out translation loss a checkpoint is kept by, per member: eq. 6 without the adversarial term
        (D changes while training, so its loss is no yardstick across iterations)."""
        return self.cfg.lambda_dyn * out["dyn"] + self.cfg.lambda_id * out["id"] + self.cfg.lambda_hand * out["hand"]


def _normalised(tr: Translator, sets: dict[str, Transitions], device: str | torch.device = "cpu"
                ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """All transitions of some pairings, normalised, on ``device``, as one member's batch: (x_prev, x, x2, pairing
    index), each with a leading dimension of 1."""
    x0s, xs, x2s, ps = [], [], [], []
    with torch.no_grad():
        for p, t in sets.items():
            x0s.append(tr.x_norms[p](torch.as_tensor(t.x if t.x_prev is None else t.x_prev, device=device)))
            xs.append(tr.x_norms[p](torch.as_tensor(t.x, device=device)))
            x2s.append(tr.x_norms[p](torch.as_tensor(t.x2, device=device)))
            ps.append(torch.full((len(t.x),), PAIRING_INDEX[p], dtype=torch.long, device=device))
    return torch.cat(x0s)[None], torch.cat(xs)[None], torch.cat(x2s)[None], torch.cat(ps)[None]


@dataclass
class Member:
    """One translator of a stack: its demonstrations, those held out for selection, and its seed."""

    demos: dict[str, Transitions]
    """The demonstrations G trains on, per pairing."""
    seed: int
    """Initialisation and minibatch seed."""
    held_out: dict[str, Transitions] | None = None
    """Demonstrations G never trains on; its parameters of the lowest translation loss on them are kept."""


def train_translators(members: list[Member], random_x: dict[str, Transitions], y_random: np.ndarray,
                      dyn: DynamicsModels, cfg: TranslatorConfig, std_floor: float = 1e-2,
                      logs: list[Callable[[dict, int], None] | None] | None = None, progress=None,
                      *, tl: TaskLayout, kinematics: Kinematics | None = None, device: str | torch.device = "cpu"
                      ) -> tuple[list[Translator], list[dict]]:
    """Train the translators of several members of one configuration (seeds, restarts) as one stacked model: G and D
    with eq. 6 (frozen F, F^-1) on ``device``. Each member has its own initialisation, demonstrations, minibatches
    and checkpoint; its result is the same bits whether it trains alone or in any stack (a test checks). Returns one
    translator (a stack of one, on the CPU) and one dict of training statistics per member.

    Every ``cfg.select_every`` iterations a member's translation loss on its held-out demonstrations is measured and
    it keeps its G of the lowest value (without them, the last iterate). ``kinematics`` is required with
    ``cfg.kinematics == 'forward'`` (the arms whose end columns G does not output).
    """
    if not members:
        raise ValueError("train_translators needs at least one member")
    torch.set_num_threads(cfg.torch_threads)
    dyn = dyn.eval()
    for prm in dyn.parameters():
        prm.requires_grad_(False)
    if cfg.kinematics == "forward" and kinematics is None:
        raise ValueError("translator.kinematics = 'forward' needs the arms' kinematics; this task has none")
    y_cols = tl.state_columns("Y")
    d_cols = None if cfg.disc_input == "state" else [i for i, c in enumerate(y_cols) if c not in tl.object_cols]
    gens = [torch.Generator().manual_seed(m.seed) for m in members]
    tr = Translator(list(cfg.hidden), tl, kinematics=kinematics if cfg.kinematics == "forward" else None,
                    d_cols=d_cols, hand_offset=cfg.hand_offset, n=len(members), generators=gens)
    tr.y_mean.copy_(dyn.y_norm.mean)
    tr.y_std.copy_(dyn.y_norm.std)
    fit_x_normalizers(tr, dyn, random_x, std_floor, cfg.object, cfg.hand_skip, tl=tl)
    try:
        tr.to(device)
        dyn.to(device)
        return _train_stack(tr, dyn, members, random_x, y_random, cfg, gens, logs or [None] * len(members),
                            progress, tl, device)
    finally:
        dyn.cpu()


def train_translator(demos: dict[str, Transitions], random_x: dict[str, Transitions], y_random: np.ndarray,
                     dyn: DynamicsModels, cfg: TranslatorConfig, seed: int, std_floor: float = 1e-2,
                     log: Callable[[dict, int], None] | None = None, progress=None,
                     *, tl: TaskLayout, kinematics: Kinematics | None = None,
                     held_out: dict[str, Transitions] | None = None, device: str | torch.device = "cpu"
                     ) -> tuple[Translator, dict]:
    """One translator (:func:`train_translators` with one member). Returns it (on the CPU) and its statistics."""
    trs, stats = train_translators([Member(demos, seed, held_out)], random_x, y_random, dyn, cfg, std_floor,
                                   [log], progress, tl=tl, kinematics=kinematics, device=device)
    return trs[0], stats[0]


RESTART_SEED_STRIDE = 1000
"""Restart r of a translator of seed s trains with seed s + RESTART_SEED_STRIDE * r (r = 0: the translator itself)."""


def restart_seed(seed: int, r: int) -> int:
    """The initialisation seed of restart ``r`` of a translator of seed ``seed``."""
    return seed + RESTART_SEED_STRIDE * r


def restart_key(r: int, key: str) -> str:
    """The name of restart ``r``'s metric ``key``: restart 0 under the plain name, restart r > 0 under
    ``restart<r>/``."""
    return key if r == 0 else f"restart{r}/{key}"


def restart_log(log: Callable[[dict, int], None] | None, r: int) -> Callable[[dict, int], None] | None:
    """``log`` with restart r's metric names (:func:`restart_key`)."""
    if log is None or r == 0:
        return log
    return lambda m, i: log({restart_key(r, k): v for k, v in m.items()}, i)


class MeanTranslator:
    """The mean translation of several translators of one configuration (restarts: same data, other initialisations);
    it translates like a :class:`Translator`."""

    def __init__(self, members: list[Translator]):
        if not members:
            raise ValueError("MeanTranslator needs at least one translator")
        self.members = members

    def translate(self, x: np.ndarray, pairing: str) -> torch.Tensor:
        """The mean of the members' normalised y_hat (one member: its own, unchanged)."""
        if len(self.members) == 1:
            return self.members[0].translate(x, pairing)
        return torch.stack([m.translate(x, pairing) for m in self.members]).mean(dim=0)


def train_restarts(demos: dict[str, Transitions], random_x: dict[str, Transitions], y_random: np.ndarray,
                   dyn: DynamicsModels, cfg: TranslatorConfig, seed: int,
                   log: Callable[[dict, int], None] | None = None, held_out: dict[str, Transitions] | None = None,
                   **kwargs) -> tuple[list[Translator], list[dict]]:
    """``cfg.restarts`` translators of one configuration (seeds seed + 1000 r), trained as one stack. Restart 0 logs
    under its own names, restart r > 0 under ``restart<r>/``."""
    members = [Member(demos, restart_seed(seed, r), held_out) for r in range(cfg.restarts)]
    return train_translators(members, random_x, y_random, dyn, cfg,
                             logs=[restart_log(log, r) for r in range(cfg.restarts)], **kwargs)


def lr_factor(kind: str, it: int, iterations: int) -> float:
    """The learning rate's share at iteration ``it`` (1-based) of ``iterations`` (``translator.lr_decay``)."""
    frac = (it - 1) / iterations
    if kind == "cosine":
        return 0.5 * (1.0 + math.cos(math.pi * frac))
    if kind == "linear":
        return 1.0 - frac
    return 1.0


def _train_stack(tr: Translator, dyn: DynamicsModels, members: list[Member], random_x: dict[str, Transitions],
                 y_random: np.ndarray, cfg: TranslatorConfig, gens: list[torch.Generator],
                 logs: list[Callable[[dict, int], None] | None], progress, tl: TaskLayout,
                 device: str | torch.device) -> tuple[list[Translator], list[dict]]:
    """The training loop of :func:`train_translators`, with ``tr`` and ``dyn`` on ``device``."""
    n = len(members)
    cache: dict = {}
    demo_s = [_Sampler(m.demos, tr, g, device, cache) for m, g in zip(members, gens)]
    rand_s = [_Sampler(random_x, tr, g, device, cache) for g in gens]
    with torch.no_grad():
        y_real_all = dyn.y_norm(torch.as_tensor(y_random, device=device))
    opt_g = Adam(tr.generator_parameters(), lr=cfg.learning_rate, betas=(0.5, 0.999))
    opt_d = Adam(tr.D.parameters(), lr=cfg.learning_rate, betas=(0.5, 0.999))
    d_loss_fn, g_loss_fn = _gan_losses(cfg.gan_loss)
    losses = _Losses(tr, dyn, cfg, tl)
    quarter = max(1, cfg.batch_size // 4)
    holds = [_normalised(tr, m.held_out, device) if m.held_out else None for m in members]
    y_dim = len(tl.state_columns("Y"))
    pools = [torch.empty(0, y_dim, device=device) for _ in members]
    best: list[tuple[float, dict | None, int]] = [(float("inf"), None, 0)] * n
    sums = [dict() for _ in members]
    curves: list[list[dict]] = [[] for _ in members]
    t0 = time.perf_counter()
    for it in range(1, cfg.iterations + 1):
        if cfg.lr_decay != "none":
            for opt in (opt_g, opt_d):
                for group in opt.param_groups:
                    group["lr"] = cfg.learning_rate * lr_factor(cfg.lr_decay, it, cfg.iterations)
        batch = []
        for k in range(n):
            xd0, xd, xd2, pd_ = demo_s[k].sample(quarter)
            xr0, xr, xr2, pr = rand_s[k].sample(quarter)
            batch.append((torch.cat([xd0, xr0]), torch.cat([xd, xr]), torch.cat([xd2, xr2]), torch.cat([pd_, pr])))
        x0, x, x2, pidx = (torch.stack(parts) for parts in zip(*batch))
        n_demo = 2 * quarter  # the batch is [demonstrations, X random], each half both pairings
        out = losses(x0, x, x2, pidx)
        y_hat = out["y_hat"]
        # --- D step (fakes detached; with a pool, half of them come from past generators, as in Cycle-Dynamics)
        y_adv = y_hat if cfg.adv_on == "all" else y_hat[:, n_demo:]
        fake = y_adv.detach()
        fakes, reals = [], []
        for k in range(n):
            fake_k = fake[k]
            if cfg.history_size:
                if len(pools[k]):
                    n_old = len(fake_k) // 2
                    old = pools[k][torch.randint(0, len(pools[k]), (n_old,), generator=gens[k]).to(device)]
                    fake_d = torch.cat([fake_k[: len(fake_k) - n_old], old])
                else:
                    fake_d = fake_k
                pools[k] = torch.cat([pools[k], fake_k])[-cfg.history_size:]
            else:
                fake_d = fake_k
            fakes.append(fake_d)
            reals.append(y_real_all[torch.randint(0, len(y_real_all), (y_adv.shape[1],), generator=gens[k])
                                    .to(device)])
        y_real, fake_d = torch.stack(reals), torch.stack(fakes)
        d_both = tr.disc(torch.cat([y_real, fake_d], dim=1))
        d_real, d_fake = d_both[:, :y_real.shape[1]], d_both[:, y_real.shape[1]:]
        l_d = d_loss_fn(d_real, d_fake)
        opt_d.zero_grad(set_to_none=True)
        l_d.sum().backward()
        opt_d.step()
        # --- G step (D frozen: its weight gradients would be thrown away)
        tr.D.requires_grad_(False)
        l_adv = g_loss_fn(tr.disc(y_adv))
        loss = (cfg.lambda_adv * l_adv + cfg.lambda_dyn * out["dyn"] + cfg.lambda_id * out["id"]
                + cfg.lambda_hand * out["hand"])
        opt_g.zero_grad(set_to_none=True)
        loss.sum().backward()
        opt_g.step()
        tr.D.requires_grad_(True)
        with torch.no_grad():
            acc = 0.5 * ((d_real > 0).float().mean(dim=(1, 2)) + (d_fake < 0).float().mean(dim=(1, 2)))
            values = torch.stack([l_d, l_adv, out["dyn"], out["id"], out["hand"], loss, acc]).detach().cpu().numpy()
        for k in range(n):
            check_finite(float(values[5, k]), "the translator's G loss", it)
            check_finite(float(values[0, k]), "the translator's D loss", it)
            for j, key in enumerate(("loss/D", "loss/adv", "loss/dyn", "loss/id", "loss/hand", "loss/G_total",
                                     "D/accuracy")):
                sums[k][key] = sums[k].get(key, 0.0) + float(values[j, k])
        if progress is not None:
            progress.update(n)
        log_now = it % cfg.log_every == 0 or it == cfg.iterations
        select_now = it % cfg.select_every == 0 or it == cfg.iterations
        if not (log_now or select_now):
            continue
        for k in range(n):
            point = None
            if log_now:
                cnt = cfg.log_every if it % cfg.log_every == 0 else it % cfg.log_every
                point = {key: v / cnt for key, v in sums[k].items()}
                sums[k] = {}
            if holds[k] is not None and select_now:
                one = tr.member(k)
                with torch.no_grad():
                    h = _Losses(one, dyn, cfg, tl)(*holds[k])
                    sel = float(_Losses(one, dyn, cfg, tl).selection(h)[0])
                point = point or {}
                point.update({"heldout/selection_loss": sel, "heldout/dyn": float(h["dyn"][0]),
                              "heldout/id": float(h["id"][0])})
                if sel < best[k][0]:
                    best[k] = (sel, one.state_dict(), it)
            if point is not None:
                curves[k].append({"iteration": it, **point})
                if logs[k]:
                    logs[k](point, it)
    wall = time.perf_counter() - t0
    out_trs, out_stats = [], []
    for k in range(n):
        one = tr.member(k)
        if best[k][1] is not None:  # the kept G (and hand offset); D stays the last iterate's
            state = one.state_dict()
            state.update({key: v for key, v in best[k][1].items() if not key.startswith("D.")})
            one.load_state_dict(state)
        one.cpu().eval()
        final = {key: v for key, v in (curves[k][-1] if curves[k] else {}).items() if key != "iteration"}
        out_trs.append(one)
        out_stats.append({"wall_time_s": wall, "iterations_per_s": cfg.iterations / wall, "curve": curves[k],
                          "final": final, "stack_size": n,
                          "selected_iteration": best[k][2] if best[k][1] is not None else cfg.iterations,
                          "selected_heldout_loss": best[k][0] if best[k][1] is not None else None})
    return out_trs, out_stats


def translator_diagnostics(tr: Translator, dyn: DynamicsModels, cfg: TranslatorConfig,
                           demos: dict[str, Transitions], random_x: dict[str, Transitions], y_random: np.ndarray,
                           *, tl: TaskLayout, kinematics: Kinematics | None = None,
                           max_random: int = 20_000, seed: int = 0) -> dict:
    """What a trained translator (one member) does, measured on demonstrations (not trained on) and random motion.

    * ``dyn/*``: L_dyn split by the real robot's columns, the missing robot's and the object's;
    * ``D/*``: the discriminator's accuracy on translated demonstrations, on translated X random motion and on
      real Y random motion (0.5 on translated data = D cannot tell them from Y);
    * ``labels/real_robot_rmse``: F^-1's labels for the real robot against its recorded actions (normalised
      torque units; needs the recorded actions in ``demos``);
    * ``fk/missing_robot_ee_error_m`` (and ``real_robot``): an arm's translated end position against the forward
      kinematics of its translated joint angles (needs ``kinematics``).
    """
    gen = torch.Generator().manual_seed(seed)
    losses = _Losses(tr, dyn, cfg, tl)
    out: dict[str, float] = {}
    with torch.no_grad():
        x0, x, x2, pidx = _normalised(tr, demos)
        h = losses(x0, x, x2, pidx)
        out.update({f"dyn/{k}": v for k, v in losses.dyn_split(h["dyn_sq"], pidx).items()})
        out["dyn/all"] = float(h["dyn"][0])
        out["id/real_robot"] = float(h["id"][0])
        sub = {p: t.subset(torch.randperm(len(t.x), generator=gen)[:max_random // 2].numpy())
               for p, t in random_x.items()}
        xr0, xr, _, pr = _normalised(tr, sub)
        yr = tr.generate(xr, pr, xr0 if len(tr.fk_q) else None)
        y_real = dyn.y_norm(torch.as_tensor(y_random[torch.randperm(len(y_random), generator=gen)[:max_random]
                                                       .numpy()]))[None]
        out["D/accuracy_translated_demos"] = float((tr.disc(h["y_hat"]) < 0).float().mean())
        out["D/accuracy_translated_random"] = float((tr.disc(yr) < 0).float().mean())
        out["D/accuracy_real_y"] = float((tr.disc(y_real) > 0).float().mean())
        pidx, y_hat, a_tilde = pidx[0], h["y_hat"][0], h["a_tilde"][0]
        if all(t.a is not None for t in demos.values()):
            n_a = len(tl.arm_action_columns("r1"))
            errs = []
            for p, t in demos.items():
                m = pidx == PAIRING_INDEX[p]
                a_hat = torch.clamp(a_tilde[m], -1.0, 1.0)
                sl = slice(0, n_a) if layout.robot_arm(p) == "r1" else slice(n_a, 2 * n_a)
                errs.append(((a_hat[:, sl] - torch.tensor(t.a)) ** 2).mean(dim=1))
            out["labels/real_robot_rmse"] = float(torch.cat(errs).mean().sqrt())
        if kinematics is not None:
            y_raw = dyn.y_norm.inverse(y_hat)
            for p in layout.PAIRINGS:
                m = pidx == PAIRING_INDEX[p]
                real = layout.robot_arm(p)
                for k, arm in enumerate(kinematics.arms):
                    fk = forward_kinematics(y_raw[m][:, arm.q], torch.as_tensor(arm.links), torch.as_tensor(arm.base))
                    err = torch.linalg.norm(fk - y_raw[m][:, arm.ee], dim=-1)
                    key = "real_robot" if (k == 0) == (real == "r1") else "missing_robot"
                    out.setdefault(f"fk/{key}_ee_error_m", []).append(err)
            for key in ("real_robot", "missing_robot"):
                out[f"fk/{key}_ee_error_m"] = float(torch.cat(out[f"fk/{key}_ee_error_m"]).mean())
    return out


def translate_demos(tr: Translator | MeanTranslator, dyn: DynamicsModels, demos_path: dict[str, str],
                    episodes: dict[str, list[int]], cfg: TranslatorConfig, dt: float, tl: TaskLayout,
                    action_bounds: tuple[float, float] | None = (-1.0, 1.0)) -> pd.DataFrame:
    """Translate every chosen demonstration of both pairings into Y states with BC action labels (raw units).

    ``action_bounds`` clips the inverse model's labels to the action space (None: no clipping).
    """
    y_cols = tl.state_columns("Y")
    a_cols = tl.action_columns("Y")
    frames = []
    ep_out = 0
    for pairing, path in demos_path.items():
        cols = tl.canonical_x_columns(pairing)
        df = data.read_transitions(path, kind="demos", domain=pairing, task=tl.name)
        df = df[df.episode_index.isin(episodes[pairing])]
        robot = layout.robot_arm(pairing)
        for src_ep, g in df.groupby("episode_index", sort=True):
            g = g.sort_values("frame_index")
            x = g[[layout.STATE_PREFIX + c for c in cols]].to_numpy(np.float32)
            x_last = g[[layout.NEXT_STATE_PREFIX + c for c in cols]].to_numpy(np.float32)[-1:]
            y_n = tr.translate(np.concatenate([x, x_last]), pairing)
            with torch.no_grad():
                a_hat = dyn.inverse_model(y_n[:-1], y_n[1:])
                if action_bounds is not None:
                    a_hat = torch.clamp(a_hat, *action_bounds)
                a_hat = a_hat.numpy()
                y = dyn.y_norm.inverse(y_n).numpy()
            if cfg.labels == "recorded_robot":
                rec = g[[layout.ACTION_PREFIX + c for c in tl.arm_action_columns(robot)]].to_numpy()
                n_a = len(tl.arm_action_columns("r1"))
                sl = slice(0, n_a) if robot == "r1" else slice(n_a, 2 * n_a)
                a_hat[:, sl] = rec
            out = pd.DataFrame(y[:-1], columns=[layout.STATE_PREFIX + c for c in y_cols])
            out[[layout.ACTION_PREFIX + c for c in a_cols]] = a_hat
            out[[layout.NEXT_STATE_PREFIX + c for c in y_cols]] = y[1:]
            out.insert(0, "episode_index", ep_out)
            out.insert(1, "frame_index", np.arange(len(g)))
            out.insert(2, "timestamp", np.arange(len(g)) * dt)
            out["source_pairing"] = pairing
            out["source_episode_index"] = int(src_ep)
            frames.append(out)
            ep_out += 1
    return pd.concat(frames, ignore_index=True)


def translated_table(df: pd.DataFrame, metadata: dict, tl: TaskLayout) -> pa.Table:
    """The translated demonstrations as a documented Arrow table (Y layout, same conventions as every dataset)."""
    schema = data.transitions_schema(
        tl.state_columns("Y"), tl.action_columns("Y"),
        extra={"source_pairing": (pa.string(), "pairing of domain X the demonstration was translated from"),
               "source_episode_index": (pa.int64(), "episode_index of the source demonstration in data/demos")},
        metadata=metadata)
    return pa.Table.from_pandas(df[[f.name for f in schema]], schema=schema, preserve_index=False)


def translation_diagnostics(df: pd.DataFrame, demos_path: dict[str, str], episodes: dict[str, list[int]],
                            tl: TaskLayout) -> dict:
    """Compare translated states with the source where they should agree (diagnostics only, never trained on).

    * the real robot's end position, and the object's pose (m, rad): translation should keep them;
    * the translated missing robot's end position vs the human's hand (m): where the push happens.
    """
    out: dict[str, list[float]] = {"robot_ee_error_m": [], "box_position_error_m": [], "box_yaw_error_rad": [],
                                   "missing_robot_ee_to_hand_m": []}
    for pairing, path in demos_path.items():
        src = data.read_transitions(path, kind="demos", domain=pairing, task=tl.name)
        src = src[src.episode_index.isin(episodes[pairing])].sort_values(["episode_index", "frame_index"])
        tr = df[df.source_pairing == pairing].sort_values(["source_episode_index", "frame_index"])
        robot = layout.robot_arm(pairing)
        other = "r2" if robot == "r1" else "r1"
        s = layout.STATE_PREFIX

        def xy(frame: pd.DataFrame, arm: str) -> np.ndarray:
            return frame[[layout.STATE_PREFIX + c for c in tl.position_cols[arm]]].to_numpy(float)

        out["robot_ee_error_m"] += np.linalg.norm(xy(tr, robot) - xy(src, robot), axis=1).tolist()
        out["missing_robot_ee_to_hand_m"] += np.linalg.norm(xy(tr, other) - xy(src, "h"), axis=1).tolist()
        box_t = tr[[s + c for c in tl.object_cols]].to_numpy(float)
        box_s = src[[s + c for c in tl.object_cols]].to_numpy(float)
        out["box_position_error_m"] += np.linalg.norm(box_t[:, :2] - box_s[:, :2], axis=1).tolist()
        out["box_yaw_error_rad"] += np.abs(box_t[:, 2] - box_s[:, 2]).tolist()
    return {f"diag/{k}": float(np.mean(v)) for k, v in out.items()}
