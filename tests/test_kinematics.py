"""myCobot 280 kinematics: IK round trips against FK over each task's workspace (bar: <= 1 mm)."""

import numpy as np
import pytest

from lfdt.robot import kinematics as K


@pytest.mark.parametrize("task", sorted(K.TASK_PLANES))
def test_ik_round_trip_over_task_workspace(task):
    plane = K.TASK_PLANES[task]
    home = K.home_angles(task)
    (a0, a1), (b0, b1) = plane.bounds
    errors, axis_errors = [], []
    seed = home
    for u in np.linspace(a0, a1, 6):
        for v in np.linspace(b0, b1, 6):
            target = plane.to_3d(np.array([u, v]))
            q = K.inverse(target, plane.tool_axis, seed)
            pose = K.forward(q)
            errors.append(np.linalg.norm(pose[:3, 3] - target))
            axis_errors.append(np.degrees(np.arccos(np.clip(pose[:3, 2] @ np.asarray(plane.tool_axis), -1, 1))))
            lo = np.array([lim[0] for lim in K.JOINT_LIMITS_DEG])
            hi = np.array([lim[1] for lim in K.JOINT_LIMITS_DEG])
            assert np.all(q >= lo) and np.all(q <= hi)
            seed = q  # warm start from the neighbour, as the controller does from the current angles
    assert max(errors) <= 1.0, f"max round-trip error {max(errors):.3f} mm"
    assert max(axis_errors) < 0.5


def test_ik_from_random_joint_configurations():
    rng = np.random.default_rng(0)
    home = K.home_angles("block_push")
    worst = 0.0
    for _ in range(30):
        q_true = home + rng.uniform(-15, 15, 6)
        pose = K.forward(q_true)
        q = K.inverse(pose[:3, 3], pose[:3, 2], home)
        worst = max(worst, float(np.linalg.norm(K.position(q) - pose[:3, 3])))
    assert worst <= 1.0


def test_fk_zero_pose_is_the_arm_standing_up():
    p = K.position(np.zeros(6))
    d = K.DH()
    assert p[2] == pytest.approx(d.d1 + d.a2 + d.a3 + d.d5)


def test_unreachable_target_is_refused():
    with pytest.raises(ValueError, match="no solution"):
        K.inverse([600.0, 0.0, 100.0], (0, 0, -1), K.home_angles("block_push"))
