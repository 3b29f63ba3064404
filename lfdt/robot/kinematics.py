"""Forward and inverse kinematics of the myCobot 280 (6 revolute joints), in millimetres and degrees.

Standard Denavit-Hartenberg parameters after Elephant Robotics' published table (d1, a2, a3, d4, d5, d6);
the defaults are the published URDF link offsets and should be calibrated on a real arm (the
published d4 differs between sources: 63.4 / 64.62 / 66.39 mm). The inverse kinematics is our own:
damped least squares on position and tool orientation, warm-started from the current angles, inside
the joint limits. Each task fixes the tool orientation and moves the tool in one plane:

* block push: the tool points down, the end moves in a horizontal plane (z fixed);
* peg insertion: the tool points along +x (horizontal), the end moves in a vertical plane (y fixed).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

JOINT_LIMITS_DEG: tuple[tuple[float, float], ...] = (
    (-168.0, 168.0), (-135.0, 135.0), (-150.0, 150.0), (-145.0, 145.0), (-155.0, 160.0), (-180.0, 180.0))
"""myCobot 280 joint limits (J1..J6), degrees, from the manufacturer's documentation."""


@dataclass(frozen=True)
class DH:
    """Standard DH parameters of the myCobot 280, mm (calibrate d4 on your arm)."""

    d1: float = 131.56
    a2: float = 110.4
    a3: float = 96.0
    d4: float = 64.62
    d5: float = 73.18
    d6: float = 45.6

    def table(self) -> list[tuple[float, float, float, float]]:
        """(theta offset rad, d mm, a mm, alpha rad) per joint."""
        return [(0.0, self.d1, 0.0, math.pi / 2), (-math.pi / 2, 0.0, -self.a2, 0.0), (0.0, 0.0, -self.a3, 0.0),
                (-math.pi / 2, self.d4, 0.0, math.pi / 2), (math.pi / 2, self.d5, 0.0, -math.pi / 2),
                (0.0, self.d6, 0.0, 0.0)]


def _dh_matrix(theta: float, d: float, a: float, alpha: float) -> np.ndarray:
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return np.array([[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st], [0, sa, ca, d], [0, 0, 0, 1]])


def forward(angles_deg, dh: DH = DH()) -> np.ndarray:
    """4x4 pose of the flange in the base frame (mm) for joint angles in degrees."""
    t = np.eye(4)
    for q, (off, d, a, alpha) in zip(np.radians(np.asarray(angles_deg, dtype=float)), dh.table()):
        t = t @ _dh_matrix(q + off, d, a, alpha)
    return t


def position(angles_deg, dh: DH = DH()) -> np.ndarray:
    """Flange position (x, y, z) in mm."""
    return forward(angles_deg, dh)[:3, 3]


@dataclass(frozen=True)
class TaskPlane:
    """A task's tool orientation and the plane its end moves in (base frame, mm)."""

    name: str
    """'block_push' or 'peg_insertion'."""
    tool_axis: tuple[float, float, float]
    """Direction the tool (flange z axis) points to."""
    fixed_axis: int
    """Axis held constant: 2 (z) for a horizontal plane, 1 (y) for a vertical plane."""
    fixed_value: float
    """Value of the fixed coordinate, mm."""
    bounds: tuple[tuple[float, float], tuple[float, float]] = field(default=((120.0, 220.0), (-80.0, 80.0)))
    """Workspace of the two free coordinates (in x, y / x, z order), mm."""

    def to_3d(self, p2: np.ndarray) -> np.ndarray:
        """A point of the plane (its two free coordinates) in 3D."""
        free = [i for i in range(3) if i != self.fixed_axis]
        p = np.zeros(3)
        p[free] = p2
        p[self.fixed_axis] = self.fixed_value
        return p

    def to_2d(self, p3: np.ndarray) -> np.ndarray:
        """The two free coordinates of a 3D point."""
        return np.asarray(p3, dtype=float)[[i for i in range(3) if i != self.fixed_axis]]


TASK_PLANES: dict[str, TaskPlane] = {
    "block_push": TaskPlane("block_push", (0.0, 0.0, -1.0), 2, 100.0, ((150.0, 230.0), (-80.0, 80.0))),
    "peg_insertion": TaskPlane("peg_insertion", (1.0, 0.0, 0.0), 1, 0.0, ((130.0, 180.0), (120.0, 210.0))),
}


def _errors(angles_deg: np.ndarray, target: np.ndarray, tool_axis: np.ndarray, dh: DH) -> np.ndarray:
    t = forward(angles_deg, dh)
    # position error (mm) and tool-axis error (scaled: 1 rad of axis error weighs like 100 mm)
    return np.concatenate([t[:3, 3] - target, 100.0 * (t[:3, 2] - tool_axis)])


def inverse(target_mm, tool_axis, seed_deg, dh: DH = DH(), tol_mm: float = 0.05, iterations: int = 200,
            damping: float = 1e-2) -> np.ndarray:
    """Joint angles (deg) putting the flange at ``target_mm`` with its z axis along ``tool_axis``.

    Damped least squares from ``seed_deg`` (e.g. the current angles), clipped to the joint limits.
    Raises ValueError when it cannot reach the target within ``tol_mm`` (out of reach or of the limits).
    """
    target = np.asarray(target_mm, dtype=float)
    axis = np.asarray(tool_axis, dtype=float)
    axis = axis / np.linalg.norm(axis)
    lo = np.array([lim[0] for lim in JOINT_LIMITS_DEG])
    hi = np.array([lim[1] for lim in JOINT_LIMITS_DEG])
    q = np.clip(np.asarray(seed_deg, dtype=float), lo, hi)
    eps = 1e-3
    for _ in range(iterations):
        e = _errors(q, target, axis, dh)
        if np.linalg.norm(e[:3]) < tol_mm and np.linalg.norm(e[3:]) < 0.1:
            return q
        jac = np.empty((6, 6))
        for j in range(6):
            dq = np.zeros(6)
            dq[j] = eps
            jac[:, j] = (_errors(q + dq, target, axis, dh) - e) / eps
        step = np.linalg.solve(jac.T @ jac + damping * np.eye(6), -jac.T @ e)
        q = np.clip(q + np.clip(step, -10.0, 10.0), lo, hi)
    e = _errors(q, target, axis, dh)
    if np.linalg.norm(e[:3]) < tol_mm and np.linalg.norm(e[3:]) < 0.1:
        return q
    raise ValueError(f"IK: no solution within {tol_mm} mm for target {np.round(target, 1)} mm "
                     f"(residual {np.linalg.norm(e[:3]):.2f} mm)")


def home_angles(task: str) -> np.ndarray:
    """A comfortable joint configuration in the middle of a task's workspace (IK seed): of the solutions from a
    few seeds, the one farthest from the joint limits, degrees."""
    plane = TASK_PLANES[task]
    centre = plane.to_3d(np.array([np.mean(b) for b in plane.bounds]))
    lo = np.array([lim[0] for lim in JOINT_LIMITS_DEG])
    hi = np.array([lim[1] for lim in JOINT_LIMITS_DEG])
    best, best_margin = None, -np.inf
    for guess in ([0, -30, -60, 0, 0, 0], [0, -45, -45, -90, 0, 0], [0, -20, -90, 20, 90, 0],
                  [0, 30, -120, 0, -90, 0], [0, -60, -30, 0, 90, 0], [0, 0, -90, 0, 90, 0], [0, -30, -60, -90, 90, 0]):
        try:
            q = inverse(centre, plane.tool_axis, np.asarray(guess, dtype=float))
        except ValueError:
            continue
        margin = float(np.min(np.minimum(q - lo, hi - q) / (hi - lo)))
        if margin > best_margin:
            best, best_margin = q, margin
    if best is None:
        raise ValueError(f"no home configuration found for {task}")
    return best
