"""The translator: G, D and the X normalisers (:class:`Translator`), their skips and normalisers, the mean of several
translators, and a translator method's config."""

from __future__ import annotations

import copy

import numpy as np
import torch
import torch.nn.functional as nnf
from torch import nn

from lfdt import layout
from lfdt.dynamics import DynamicsModels
from lfdt.layout import TaskLayout
from lfdt.nets import Normalizer, StackedMLP, sin_cos
from lfdt.translation.kinematics import Kinematics
from lfdt.translation.transitions import PAIRING_INDEX, Transitions


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
