"""Eq. 6's generator losses on a batch of normalised transitions (training, checkpoint selection, diagnostics)."""

from __future__ import annotations

import torch

from lfdt import layout
from lfdt.config import TranslatorConfig
from lfdt.dynamics import DynamicsModels
from lfdt.layout import TaskLayout
from lfdt.nets import sin_cos
from lfdt.translation.model import Translator
from lfdt.translation.transitions import PAIRING_INDEX, Transitions


class Losses:
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
        self.obj_idx = torch.as_tensor(obj, dtype=torch.long, device=dev)  # the object's position, then its angle

    def __call__(self, x0: torch.Tensor, x: torch.Tensor, x2: torch.Tensor, pidx: torch.Tensor
                 ) -> dict[str, torch.Tensor]:
        """y_hat, y_hat2, the per-column squared dynamics error and the identity loss of a batch
        (``x0``: the states one step before ``x``, used only with Y's robot model)."""
        n, b = x.shape[:2]
        y_hat, y_hat2 = self.tr.generate_pair(x0, x, x2, pidx)
        a_tilde = self.dyn.inverse_model(y_hat, y_hat2)
        y_tilde = self.dyn.forward_model(y_hat, a_tilde)
        err = (y_tilde - y_hat2) / self.dyn_scale
        dyn_sq = err ** 2 if self.cfg.dyn_norm == "l2" else err.abs()  # the per-column error L_dyn averages
        y_robot = y_hat[self.robot_mask[pidx]].view(n, b, self.n_robot)
        l_id = ((y_robot - x[..., :self.n_robot]) ** 2).mean(dim=(1, 2))
        tr = self.tr
        hand = torch.gather(x, -1, tr.hand_src[pidx]) * tr.hand_scale[pidx] + tr.hand_offset[pidx]
        if tr.hand_shift is not None:
            hand = hand + tr.hand_shift[torch.arange(n, device=pidx.device)[:, None], pidx]
        l_hand = ((torch.gather(y_hat, -1, tr.hand_dst[pidx]) - hand) ** 2).mean(dim=(1, 2))
        return {"y_hat": y_hat, "y_hat2": y_hat2, "a_tilde": a_tilde, "dyn_sq": dyn_sq,
                "dyn": (dyn_sq * self.dyn_weight).mean(dim=(1, 2)),
                "id": l_id, "hand": l_hand, "side": self.side(y_hat, x, pidx)}

    def side(self, y_hat: torch.Tensor, x: torch.Tensor, pidx: torch.Tensor) -> torch.Tensor:
        """The sideways term per member: the missing robot's end and the human's hand, each across the object in the
        object's frame (the object's pose as translated), squared difference in units of Y's spread of that end's
        first coordinate (``translator.lambda_side``)."""
        tr = self.tr
        dst = tr.hand_dst[pidx]  # (n, b, 2): the missing robot's end columns of y
        std, mean = tr.y_std[dst], tr.y_mean[dst]
        end = torch.gather(y_hat, -1, dst) * std + mean
        hand = (torch.gather(x, -1, tr.hand_src[pidx]) * tr.hand_scale[pidx] + tr.hand_offset[pidx]) * std + mean
        obj = y_hat.index_select(-1, self.obj_idx) * tr.y_std[self.obj_idx] + tr.y_mean[self.obj_idx]
        sin, cos = sin_cos(obj[..., 2])
        across = ((end - hand)[..., 0] * cos + (end - hand)[..., 1] * sin) / std[..., 0]
        return (across ** 2).mean(dim=1)

    def dyn_split(self, dyn_sq: torch.Tensor, pidx: torch.Tensor) -> dict[str, float]:
        """L_dyn split by the real robot's columns, the missing robot's and the object's (one member)."""
        dyn_sq, pidx = dyn_sq[0], pidx[0]
        real = self.robot_mask[pidx]
        missing = ~real & ~self.object_mask
        return {"real_robot": float(dyn_sq[real].mean()), "missing_robot": float(dyn_sq[missing].mean()),
                "object": float(dyn_sq[:, self.object_mask].mean())}

    def selection(self, out: dict[str, torch.Tensor]) -> torch.Tensor:
        """The held-out translation loss a checkpoint is kept by, per member: eq. 6 without the adversarial term
        (D changes while training, so its loss is no yardstick across iterations), with the hand and sideways terms
        where they are on."""
        return (self.cfg.lambda_dyn * out["dyn"] + self.cfg.lambda_id * out["id"] + self.cfg.lambda_hand * out["hand"]
                + self.cfg.lambda_side * out["side"])


def normalised(tr: Translator, sets: dict[str, Transitions], device: str | torch.device = "cpu"
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
