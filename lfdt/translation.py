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
from lfdt.nets import Normalizer, check_finite, mlp

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
    phi = torch.cumsum(q, dim=-1)
    return torch.stack([base[0] - (links * torch.sin(phi)).sum(-1), base[1] + (links * torch.cos(phi)).sum(-1)], -1)


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
    """G, D and the X normalisers of both pairings, saved as one state dict."""

    def __init__(self, hidden: list[int], tl: TaskLayout, slope: float = 0.2,
                 kinematics: Kinematics | None = None, d_cols: list[int] | None = None, hand_offset: bool = False):
        super().__init__()
        x_dim = len(tl.canonical_x_columns("R1H"))
        y_dim = len(tl.state_columns("Y"))
        self.x_norms = nn.ModuleDict({p: Normalizer(np.zeros(x_dim), np.ones(x_dim)) for p in layout.PAIRINGS})
        self.G = mlp(x_dim + len(layout.PAIRINGS), y_dim, hidden, slope)
        # the columns of y D sees (disc_input): all, or the robots' only
        d_cols = list(range(y_dim)) if d_cols is None else d_cols
        self.register_buffer("d_idx", torch.as_tensor(d_cols, dtype=torch.long))
        self.D = mlp(len(d_cols), 1, hidden, slope)
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
        # hand_offset: a constant offset per pairing between the hand and the missing robot's end, trained with G
        # (Y's normalised units); only then, so that translators without it keep their state dicts unchanged
        self.hand_shift = nn.Parameter(torch.zeros(n_p, 2)) if hand_offset else None

    def generator_parameters(self) -> list[nn.Parameter]:
        """What G's optimiser trains: G's weights, and the learnt hand offset where there is one."""
        return [*self.G.parameters(), *([] if self.hand_shift is None else [self.hand_shift])]

    def hand_offset_m(self, tl: TaskLayout) -> dict[str, float]:
        """The learnt hand offset in metres (the missing robot's end minus the hand), keyed by the missing robot's
        Y column; empty without one."""
        if self.hand_shift is None:
            return {}
        cols = tl.state_columns("Y")
        shift = self.hand_shift.detach() * self.y_std[self.hand_dst]
        return {cols[int(j)]: float(shift[i, k]) for i in PAIRING_INDEX.values()
                for k, j in enumerate(self.hand_dst[i])}

    def generate(self, x_n: torch.Tensor, pairing_idx: torch.Tensor,
                 x_prev_n: torch.Tensor | None = None) -> torch.Tensor:
        """y_hat (normalised Y state) from normalised canonical x and the pairing index.

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
            copied = torch.gather(x_n, 1, src.clamp(min=0))
            y = y + torch.where(has, copied * self.skip_scale[pairing_idx] + self.skip_offset[pairing_idx],
                                torch.zeros_like(y))
        return y

    def generate_pair(self, x0: torch.Tensor, x: torch.Tensor, x2: torch.Tensor, pairing_idx: torch.Tensor
                      ) -> tuple[torch.Tensor, torch.Tensor]:
        """(y_hat_t, y_hat_t+1) of transitions (x, x2) whose previous states are x0, in one pass of G."""
        n = len(x)
        if not len(self.fk_q):
            y = self._raw_generate(torch.cat([x, x2]), pairing_idx.repeat(2))
            return y[:n], y[n:]
        y = self._raw_generate(torch.cat([x0, x, x2]), pairing_idx.repeat(3))
        y0, y1, y2 = y[:n], y[n:2 * n], y[2 * n:]
        return self.apply_kinematics(y1, y0), self.apply_kinematics(y2, y1)

    def apply_kinematics(self, y_n: torch.Tensor, y_prev_n: torch.Tensor | None = None) -> torch.Tensor:
        """Each arm's end columns from its joint angles; its joint velocities from the change since ``y_prev_n``
        (when given). Normalised units in and out."""
        qi, dqi, ei = self.fk_q, self.fk_dq, self.fk_ee  # (arms, joints), (arms, joints), (arms, 2)
        q = y_n[:, qi] * self.y_std[qi] + self.y_mean[qi]  # (batch, arms, joints)
        phi = torch.cumsum(q, dim=-1)
        ee = torch.stack([self.fk_base[:, 0] - (self.fk_links * torch.sin(phi)).sum(-1),
                          self.fk_base[:, 1] + (self.fk_links * torch.cos(phi)).sum(-1)], dim=-1)
        y_n = y_n.clone()
        y_n[:, ei.reshape(-1)] = ((ee - self.y_mean[ei]) / self.y_std[ei]).reshape(len(y_n), -1)
        if y_prev_n is not None:
            q_prev = y_prev_n[:, qi] * self.y_std[qi] + self.y_mean[qi]
            dq = ((q - q_prev) / self.fk_dt - self.y_mean[dqi]) / self.y_std[dqi]
            y_n[:, dqi.reshape(-1)] = dq.reshape(len(y_n), -1)
        return y_n

    def disc(self, y: torch.Tensor) -> torch.Tensor:
        """D's logit that ``y`` (normalised Y states) is real, from the columns D sees."""
        return self.D(y.index_select(-1, self.d_idx))

    def translate(self, x: np.ndarray, pairing: str) -> torch.Tensor:
        """Normalised y_hat for the raw canonical states of one episode of a pairing, in time order (no gradient).

        The first state is the episode's start (the arms at rest)."""
        with torch.no_grad():
            xt = self.x_norms[pairing](torch.as_tensor(x, dtype=torch.float32))
            idx = torch.full((len(xt),), PAIRING_INDEX[pairing], dtype=torch.long)
            return self.generate(xt, idx, torch.cat([xt[:1], xt[:-1]]))


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
    if kind == "bce":
        def d_loss(real, fake):
            return (nnf.binary_cross_entropy_with_logits(real, torch.ones_like(real))
                    + nnf.binary_cross_entropy_with_logits(fake, torch.zeros_like(fake)))

        def g_loss(fake):
            return nnf.binary_cross_entropy_with_logits(fake, torch.ones_like(fake))
    else:
        def d_loss(real, fake):
            return ((real - 1) ** 2).mean() + (fake ** 2).mean()

        def g_loss(fake):
            return ((fake - 1) ** 2).mean()
    return d_loss, g_loss


class _Sampler:
    """Draws the index sets of one batch from per-pairing tensors."""

    def __init__(self, sets: dict[str, Transitions], translator: Translator, gen: torch.Generator,
                 device: str | torch.device = "cpu"):
        self.gen, self.device = gen, device
        self.x, self.x2, self.x0, self.n = {}, {}, {}, {}
        for p, tr in sets.items():
            norm = translator.x_norms[p]
            with torch.no_grad():
                self.x[p] = norm(torch.as_tensor(tr.x, device=device))
                self.x2[p] = norm(torch.as_tensor(tr.x2, device=device))
                self.x0[p] = self.x[p] if tr.x_prev is None else norm(torch.as_tensor(tr.x_prev, device=device))
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
    """The generator's losses of eq. 6 on one batch, reusable for training, selection and diagnostics."""

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
        y_hat, y_hat2 = self.tr.generate_pair(x0, x, x2, pidx)
        a_tilde = self.dyn.inverse_model(y_hat, y_hat2)
        y_tilde = self.dyn.forward_model(y_hat, a_tilde)
        dyn_sq = ((y_tilde - y_hat2) / self.dyn_scale) ** 2
        y_robot = y_hat[self.robot_mask[pidx]].view(-1, self.n_robot)
        l_id = ((y_robot - x[:, :self.n_robot]) ** 2).mean()
        tr = self.tr
        hand = torch.gather(x, 1, tr.hand_src[pidx]) * tr.hand_scale[pidx] + tr.hand_offset[pidx]
        if tr.hand_shift is not None:
            hand = hand + tr.hand_shift[pidx]
        l_hand = ((torch.gather(y_hat, 1, tr.hand_dst[pidx]) - hand) ** 2).mean()
        return {"y_hat": y_hat, "y_hat2": y_hat2, "a_tilde": a_tilde, "dyn_sq": dyn_sq,
                "dyn": (dyn_sq * self.dyn_weight).mean(),
                "id": l_id, "hand": l_hand}

    def dyn_split(self, dyn_sq: torch.Tensor, pidx: torch.Tensor) -> dict[str, float]:
        """L_dyn split by the real robot's columns, the missing robot's and the object's."""
        real = self.robot_mask[pidx]
        missing = ~real & ~self.object_mask
        return {"real_robot": float(dyn_sq[real].mean()), "missing_robot": float(dyn_sq[missing].mean()),
                "object": float(dyn_sq[:, self.object_mask].mean())}

    def selection(self, out: dict[str, torch.Tensor]) -> torch.Tensor:
        """The held-out translation loss a checkpoint is kept by: eq. 6 without the adversarial term (D changes
        while training, so its loss is no yardstick across iterations)."""
        return self.cfg.lambda_dyn * out["dyn"] + self.cfg.lambda_id * out["id"] + self.cfg.lambda_hand * out["hand"]


def _normalised(tr: Translator, sets: dict[str, Transitions], device: str | torch.device = "cpu"
                ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """All transitions of some pairings, normalised, on ``device``: (x_prev, x, x2, pairing index)."""
    x0s, xs, x2s, ps = [], [], [], []
    with torch.no_grad():
        for p, t in sets.items():
            x0s.append(tr.x_norms[p](torch.as_tensor(t.x if t.x_prev is None else t.x_prev, device=device)))
            xs.append(tr.x_norms[p](torch.as_tensor(t.x, device=device)))
            x2s.append(tr.x_norms[p](torch.as_tensor(t.x2, device=device)))
            ps.append(torch.full((len(t.x),), PAIRING_INDEX[p], dtype=torch.long, device=device))
    return torch.cat(x0s), torch.cat(xs), torch.cat(x2s), torch.cat(ps)


def train_translator(demos: dict[str, Transitions], random_x: dict[str, Transitions], y_random: np.ndarray,
                     dyn: DynamicsModels, cfg: TranslatorConfig, seed: int, std_floor: float = 1e-2,
                     log: Callable[[dict, int], None] | None = None, progress=None,
                     *, tl: TaskLayout, kinematics: Kinematics | None = None,
                     held_out: dict[str, Transitions] | None = None, device: str | torch.device = "cpu"
                     ) -> tuple[Translator, dict]:
    """Train G and D with eq. 6 (frozen F, F^-1) on ``device``. Returns the translator (on the CPU, as ``dyn``
    is left) and training statistics.

    ``held_out``: demonstrations G never trains on; every ``cfg.select_every`` iterations the translation loss on
    them is measured and G keeps the parameters of its lowest value (without them, the last iterate is kept).
    ``kinematics`` is required with ``cfg.kinematics == 'forward'`` (the arms whose end columns G does not output).
    """
    torch.manual_seed(seed)
    torch.set_num_threads(cfg.torch_threads)
    gen = torch.Generator().manual_seed(seed)
    dyn = dyn.eval()
    for prm in dyn.parameters():
        prm.requires_grad_(False)
    if cfg.kinematics == "forward" and kinematics is None:
        raise ValueError("translator.kinematics = 'forward' needs the arms' kinematics; this task has none")
    y_cols = tl.state_columns("Y")
    d_cols = None if cfg.disc_input == "state" else [i for i, c in enumerate(y_cols) if c not in tl.object_cols]
    tr = Translator(list(cfg.hidden), tl, kinematics=kinematics if cfg.kinematics == "forward" else None,
                    d_cols=d_cols, hand_offset=cfg.hand_offset)
    tr.y_mean.copy_(dyn.y_norm.mean)
    tr.y_std.copy_(dyn.y_norm.std)
    fit_x_normalizers(tr, dyn, random_x, std_floor, cfg.object, cfg.hand_skip, tl=tl)
    try:
        tr.to(device)
        dyn.to(device)
        return _train_translator(tr, dyn, demos, random_x, y_random, cfg, gen, log, progress, tl, held_out, device)
    finally:
        tr.cpu()
        dyn.cpu()


RESTART_SEED_STRIDE = 1000
"""Restart r of a translator of seed s trains with seed s + RESTART_SEED_STRIDE * r (r = 0: the translator itself)."""


def restart_seed(seed: int, r: int) -> int:
    """The initialisation seed of restart ``r`` of a translator of seed ``seed``."""
    return seed + RESTART_SEED_STRIDE * r


def restart_key(r: int, key: str) -> str:
    """The name of restart ``r``'s metric ``key``: restart 0 under the plain name, restart r > 0 under
    ``restart<r>/``."""
    return key if r == 0 else f"restart{r}/{key}"


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
                   log: Callable[[dict, int], None] | None = None, **kwargs) -> tuple[list[Translator], list[dict]]:
    """``cfg.restarts`` translators of one configuration (:func:`train_translator` with seeds seed + 1000 r).
    Restart 0 logs under its own names, restart r > 0 under ``restart<r>/``."""
    trs, stats = [], []
    for r in range(cfg.restarts):
        log_r = log if r == 0 or log is None else (
            lambda m, i, r=r: log({restart_key(r, k): v for k, v in m.items()}, i))
        tr, st = train_translator(demos, random_x, y_random, dyn, cfg, restart_seed(seed, r), log=log_r,
                                  **kwargs)
        trs.append(tr)
        stats.append(st)
    return trs, stats


def _train_translator(tr: Translator, dyn: DynamicsModels, demos: dict[str, Transitions],
                      random_x: dict[str, Transitions], y_random: np.ndarray, cfg: TranslatorConfig,
                      gen: torch.Generator, log: Callable[[dict, int], None] | None, progress, tl: TaskLayout,
                      held_out: dict[str, Transitions] | None, device: str | torch.device) -> tuple[Translator, dict]:
    """The training loop of :func:`train_translator`, with ``tr`` and ``dyn`` on ``device``."""
    demo_s, rand_s = _Sampler(demos, tr, gen, device), _Sampler(random_x, tr, gen, device)
    with torch.no_grad():
        y_real_all = dyn.y_norm(torch.as_tensor(y_random, device=device))
    opt_g = torch.optim.Adam(tr.generator_parameters(), lr=cfg.learning_rate, betas=(0.5, 0.999))
    opt_d = torch.optim.Adam(tr.D.parameters(), lr=cfg.learning_rate, betas=(0.5, 0.999))
    d_loss_fn, g_loss_fn = _gan_losses(cfg.gan_loss)
    losses = _Losses(tr, dyn, cfg, tl)
    quarter = max(1, cfg.batch_size // 4)
    hold = _normalised(tr, held_out, device) if held_out else None
    pool = torch.empty(0, len(tl.state_columns("Y")), device=device)
    best = (float("inf"), None, 0)
    sums: dict[str, float] = {}
    curve = []
    t0 = time.perf_counter()
    for it in range(1, cfg.iterations + 1):
        xd0, xd, xd2, pd_ = demo_s.sample(quarter)
        xr0, xr, xr2, pr = rand_s.sample(quarter)
        x0, x, x2, pidx = torch.cat([xd0, xr0]), torch.cat([xd, xr]), torch.cat([xd2, xr2]), torch.cat([pd_, pr])
        out = losses(x0, x, x2, pidx)
        y_hat = out["y_hat"]
        # --- D step (fakes detached; with a pool, half of them come from past generators, as in Cycle-Dynamics)
        y_adv = y_hat if cfg.adv_on == "all" else y_hat[len(xd):]  # the batch is [demonstrations, X random]
        fake = y_adv.detach()
        if cfg.history_size:
            if len(pool):
                n_old = len(fake) // 2
                old = pool[torch.randint(0, len(pool), (n_old,), generator=gen).to(device)]
                fake_d = torch.cat([fake[: len(fake) - n_old], old])
            else:
                fake_d = fake
            pool = torch.cat([pool, fake])[-cfg.history_size:]
        else:
            fake_d = fake
        y_real = y_real_all[torch.randint(0, len(y_real_all), (len(y_adv),), generator=gen).to(device)]
        d_both = tr.disc(torch.cat([y_real, fake_d]))
        d_real, d_fake = d_both[:len(y_real)], d_both[len(y_real):]
        l_d = d_loss_fn(d_real, d_fake)
        opt_d.zero_grad(set_to_none=True)
        l_d.backward()
        opt_d.step()
        # --- G step
        l_adv = g_loss_fn(tr.disc(y_adv))
        loss = (cfg.lambda_adv * l_adv + cfg.lambda_dyn * out["dyn"] + cfg.lambda_id * out["id"]
                + cfg.lambda_hand * out["hand"])
        opt_g.zero_grad(set_to_none=True)
        loss.backward()
        opt_g.step()
        check_finite(float(loss.detach()), "the translator's G loss", it)
        check_finite(float(l_d.detach()), "the translator's D loss", it)
        with torch.no_grad():
            acc = 0.5 * ((d_real > 0).float().mean() + (d_fake < 0).float().mean())
        for k, v in (("loss/D", l_d), ("loss/adv", l_adv), ("loss/dyn", out["dyn"]), ("loss/id", out["id"]),
                     ("loss/hand", out["hand"]),
                     ("loss/G_total", loss), ("D/accuracy", acc)):
            sums[k] = sums.get(k, 0.0) + v.item()
        if progress is not None:
            progress.update(1)
        point = None
        if it % cfg.log_every == 0 or it == cfg.iterations:
            n = cfg.log_every if it % cfg.log_every == 0 else it % cfg.log_every
            point = {k: v / n for k, v in sums.items()}
            sums = {}
        if hold is not None and (it % cfg.select_every == 0 or it == cfg.iterations):
            with torch.no_grad():
                h = losses(*hold)
                sel = float(losses.selection(h))
            point = point or {}
            point.update({"heldout/selection_loss": sel, "heldout/dyn": float(h["dyn"]), "heldout/id": float(h["id"])})
            if sel < best[0]:
                shift = None if tr.hand_shift is None else tr.hand_shift.detach().clone()
                best = (sel, ({k: v.clone() for k, v in tr.G.state_dict().items()}, shift), it)
        if point is not None:
            curve.append({"iteration": it, **point})
            if log:
                log(point, it)
    wall = time.perf_counter() - t0
    if best[1] is not None:
        tr.G.load_state_dict(best[1][0])
        if tr.hand_shift is not None:
            with torch.no_grad():
                tr.hand_shift.copy_(best[1][1])
    final = {k: v for k, v in (curve[-1] if curve else {}).items() if k != "iteration"}
    return tr.eval(), {"wall_time_s": wall, "iterations_per_s": cfg.iterations / wall, "curve": curve,
                       "final": final, "selected_iteration": best[2] if best[1] is not None else cfg.iterations,
                       "selected_heldout_loss": best[0] if best[1] is not None else None}


def translator_diagnostics(tr: Translator, dyn: DynamicsModels, cfg: TranslatorConfig,
                           demos: dict[str, Transitions], random_x: dict[str, Transitions], y_random: np.ndarray,
                           *, tl: TaskLayout, kinematics: Kinematics | None = None,
                           max_random: int = 20_000, seed: int = 0) -> dict:
    """What the trained translator does, measured on demonstrations (not trained on) and random motion.

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
        out["dyn/all"] = float(h["dyn"])
        out["id/real_robot"] = float(h["id"])
        sub = {p: t.subset(torch.randperm(len(t.x), generator=gen)[:max_random // 2].numpy())
               for p, t in random_x.items()}
        xr0, xr, _, pr = _normalised(tr, sub)
        yr = tr.generate(xr, pr, xr0 if len(tr.fk_q) else None)
        y_real = dyn.y_norm(torch.as_tensor(y_random[torch.randperm(len(y_random), generator=gen)[:max_random]
                                                       .numpy()]))
        out["D/accuracy_translated_demos"] = float((tr.disc(h["y_hat"]) < 0).float().mean())
        out["D/accuracy_translated_random"] = float((tr.disc(yr) < 0).float().mean())
        out["D/accuracy_real_y"] = float((tr.disc(y_real) > 0).float().mean())
        if all(t.a is not None for t in demos.values()):
            n_a = len(tl.arm_action_columns("r1"))
            errs = []
            for p, t in demos.items():
                m = pidx == PAIRING_INDEX[p]
                a_hat = torch.clamp(h["a_tilde"][m], -1.0, 1.0)
                sl = slice(0, n_a) if layout.robot_arm(p) == "r1" else slice(n_a, 2 * n_a)
                errs.append(((a_hat[:, sl] - torch.tensor(t.a)) ** 2).mean(dim=1))
            out["labels/real_robot_rmse"] = float(torch.cat(errs).mean().sqrt())
        if kinematics is not None:
            y_raw = dyn.y_norm.inverse(h["y_hat"])
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
