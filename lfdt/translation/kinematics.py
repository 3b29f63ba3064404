"""What the translator may take from Y's known robot model: the planar arms, and their end positions."""

from __future__ import annotations

from dataclasses import dataclass

import torch

from lfdt.nets import sin_cos


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


def end_positions(q: torch.Tensor, links: torch.Tensor, base: torch.Tensor) -> torch.Tensor:
    """End positions (..., 2) of a planar arm for joint angles q (..., n), differentiable."""
    sin, cos = sin_cos(torch.cumsum(q, dim=-1))
    return torch.stack([base[0] - (links * sin).sum(-1), base[1] + (links * cos).sum(-1)], -1)
