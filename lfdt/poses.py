"""Pose maths shared by the camera tracker (:mod:`lfdt.robot.tracker`) and the rig (:mod:`lfdt.rig.base`): inverse
transforms, quaternions, angles of rotations about an axis. NumPy only, so the hardware-free layers use it without
OpenCV (building a pose from a rotation vector needs ``cv2.Rodrigues``: :func:`lfdt.robot.tracker.make_pose`)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np


def invert_pose(pose: np.ndarray) -> np.ndarray:
    """Inverse of a rigid 4x4 transform."""
    rot = pose[:3, :3]
    inv = np.eye(4)
    inv[:3, :3] = rot.T
    inv[:3, 3] = -rot.T @ pose[:3, 3]
    return inv


def quaternion_from_matrix(rotation: np.ndarray) -> np.ndarray:
    """Unit quaternion ``(w, x, y, z)`` with ``w >= 0`` of a 3x3 rotation matrix."""
    m = np.asarray(rotation, dtype=np.float64)
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = np.array([0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s])
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = np.array([(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s])
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = np.array([(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s])
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = np.array([(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s])
    q /= np.linalg.norm(q)
    return -q if q[0] < 0 else q


def rotation_angle_deg(r_a: np.ndarray, r_b: np.ndarray) -> float:
    """Angle in degrees of the rotation taking ``r_a`` to ``r_b`` (both 3x3)."""
    cos = (np.trace(np.asarray(r_a).T @ np.asarray(r_b)) - 1.0) / 2.0
    return math.degrees(math.acos(float(np.clip(cos, -1.0, 1.0))))


def _unit(v: Sequence[float] | np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64).reshape(3)
    return v / np.linalg.norm(v)


def rotation_about_axis(rotation: np.ndarray, axis: Sequence[float] | np.ndarray) -> float:
    """Twist angle (radians, in (-pi, pi]) of ``rotation`` about ``axis`` (swing-twist decomposition).

    For a rotation purely about ``axis`` this is its angle (right-hand rule); for ``axis = z`` and a small
    tilt it is the usual yaw.
    """
    q = quaternion_from_matrix(rotation)
    a = _unit(axis)
    proj = float(np.dot(q[1:], a))
    return 2.0 * math.atan2(proj, q[0])


def yaw_of_normal(
    rotation: np.ndarray,
    axis: Sequence[float] | np.ndarray = (0.0, -1.0, 0.0),
    reference: Sequence[float] | np.ndarray = (0.0, 0.0, -1.0),
    normal: Sequence[float] | np.ndarray = (0.0, 0.0, 1.0),
) -> float:
    """Angle (radians) of a tag's face normal about ``axis``, measured from ``reference``.

    ``rotation`` is ``frame_from_tag``; the tag's ``normal`` (default its z axis, out of the printed face)
    and ``reference`` are projected on the plane orthogonal to ``axis`` and the signed angle between them
    (right-hand rule about ``axis``) is returned. The defaults suit a tag on a stand turning about its
    vertical axis seen by a camera (camera frame: y points down, so "up" is -y; a tag facing the camera
    has its normal along -z and yaw 0).
    """
    a = _unit(axis)
    n = np.asarray(rotation, dtype=np.float64) @ _unit(normal)
    ref = _unit(reference)
    n_p = n - np.dot(n, a) * a
    r_p = ref - np.dot(ref, a) * a
    return math.atan2(float(np.dot(np.cross(r_p, n_p), a)), float(np.dot(r_p, n_p)))
