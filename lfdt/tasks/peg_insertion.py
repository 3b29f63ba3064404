"""Peg insertion (the paper's second real task, §IV-E): one arm holds a slotted receptacle, the other a peg.

Vertical plane (x, z). Slot 1 holds the receptacle rigidly, mouth facing -x; slot 2 holds the peg (the observed
object) compliantly. The peg must enter the slot to a depth, level with it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from lfdt.tasks.base import PlanarTask

if TYPE_CHECKING:
    from lfdt.tasks.planar_env import TwinEnv

MEETING_POINT = np.array([0.12, 0.15])
"""Where the programmed robot brings the receptacle (R1H), m."""
DEPTH = 0.025
"""Insertion depth that counts as success, m."""


class PegInsertion(PlanarTask):
    """The peg insertion in the twin's vertical plane."""

    name = "peg_insertion"
    plane = ("x", "z")
    angle = "pitch"
    angle_axis = "y"
    workspace = np.array([[-0.20, 0.05], [0.20, 0.25]])

    def held_part(self, slot: int, human: bool) -> str:
        """Slot 1 holds the slotted receptacle rigidly, from behind its back wall; a person further back and
        tilted. Slot 2's peg is a separate, compliantly held body (the object)."""
        if slot != 1:
            return ""
        off, tilt = (-0.095, 0.06) if human else (-0.085, 0.0)
        gap, t, length = 0.022, 0.006, 0.06
        plate = f'type="box" size="{length / 2} 0.015 {t / 2}" rgba="0.5 0.5 0.5 1" mass="0.05"'
        return (f'<body name="slot" pos="{off} 0 0" euler="0 {tilt} 0">'
                f'<geom {plate} pos="{length / 2} 0 {gap / 2 + t / 2}"/>'
                f'<geom {plate} pos="{length / 2} 0 {-gap / 2 - t / 2}"/>'
                f'<geom type="box" size="{t / 2} 0.015 {gap / 2 + t}" pos="{length + t / 2} 0 0" '
                f'rgba="0.5 0.5 0.5 1" mass="0.05"/>'
                f'<site name="slot_mouth" pos="0 0 0" size="0.003"/></body>')

    def object_xml(self, arms: tuple[str, str]) -> str:
        """The peg, a free body with a site at its tip."""
        return ('<body name="obj" pos="0 0 0.15"><freejoint name="obj_free"/>'
                '<geom type="box" size="0.04 0.008 0.008" mass="0.05" rgba="0.2 0.7 0.3 1"/>'
                '<site name="peg_tip" pos="0.04 0 0" size="0.003"/></body>')

    def camera_xml(self) -> str:
        """Looking at the vertical plane from the front."""
        return '<camera name="view" pos="0 -0.75 0.15" xyaxes="1 0 0 0 0 1" fovy="40"/>'

    def equality_xml(self, arms: tuple[str, str]) -> str:
        """Slot 2 holds the peg compliantly: a gripper close to its rear end, a hand further back and tilted."""
        if arms[1] == "h":
            return ('<weld body1="obj" body2="hand" relpose="-0.065 0 0.0 0.9997 0 0.025 0" '
                    'solref="0.01 1"/>')  # peg centre 6.5 cm ahead of the hand, tilted ~3 deg
        return '<weld body1="obj" body2="ee2" relpose="-0.05 0 0 1 0 0 0" solref="0.01 1"/>'

    def reset(self, env: TwinEnv, rng: np.random.Generator) -> list[np.ndarray]:
        """The receptacle near (0.15, 0.15), the peg's holder near (-0.12, 0.15)."""
        hole = np.array([0.15, 0.15]) + rng.uniform(-0.02, 0.02, 2)
        peg_hand = np.array([-0.12, 0.15]) + rng.uniform(-0.02, 0.02, 2)
        return [hole, peg_hand]

    def settle(self, env: TwinEnv) -> None:
        """Let the compliant grasp of the peg settle before the episode starts."""
        import mujoco

        for _ in range(200):
            mujoco.mj_step(env.model, env.data)
        env.data.qvel[:] = 0.0
        mujoco.mj_forward(env.model, env.data)

    def _tip_and_mouth(self, env: TwinEnv) -> tuple[np.ndarray, np.ndarray]:
        ax = list(self.axes)
        return env.data.site("peg_tip").xpos[ax], env.data.site("slot_mouth").xpos[ax]

    def info(self, env: TwinEnv) -> dict[str, Any]:
        """Success: the tip deeper than DEPTH in the slot, within 6 mm of its height, |pitch| < 0.12 rad."""
        tip, mouth = self._tip_and_mouth(env)
        depth = float(tip[0] - mouth[0])
        ok = depth > DEPTH and abs(tip[1] - mouth[1]) < 0.006 and abs(env.object_pose()[2]) < 0.12
        return {"is_success": bool(ok), "depth": depth, "height_error": float(tip[1] - mouth[1])}

    def program_waypoint(self, robot_slot: int, start: np.ndarray, obs: np.ndarray,
                         goal_line: float | None = None) -> np.ndarray:
        """Slot 1 (receptacle) to MEETING_POINT and hold; slot 2 (peg) 8 cm ahead (+x)."""
        return MEETING_POINT.copy() if robot_slot == 0 else start + (0.08, 0.0)

    def person_target(self, env: TwinEnv, human_slot: int, robot_slot: int, obs: np.ndarray) -> np.ndarray:
        """Line up 1.5 cm in front of the slot, then insert to 3.5 cm depth; the person moves what it holds."""
        hand = obs[2 * human_slot:2 * human_slot + 2]
        reach = env.cfg.human_speed * env.cfg.control_dt
        tip, mouth = self._tip_and_mouth(env)
        gap = mouth - tip  # > 0 in x while the tip is still outside the slot
        aligned = abs(gap[1]) < 0.003
        holds_peg = human_slot == 1
        want_x = (gap[0] - 0.015) if not (aligned and gap[0] < 0.02) else (gap[0] + 0.035)
        step = np.array([want_x, gap[1]]) if holds_peg else -np.array([want_x, gap[1]])
        return hand + np.clip(step, -reach, reach)

    def example_rig(self) -> tuple[dict, dict, dict, dict]:
        """Tools along their base +x: Robot2 (peg) faces +x, Robot1 (receptacle) faces -x (yaw 180); the table
        tag stands upright, facing the camera."""
        r1 = {"host": "192.168.1.11", "base": {"x_mm": 305.0, "y_mm": 0.0, "z_mm": -15.0, "yaw_deg": 180.0}}
        r2 = {"host": "192.168.1.12", "base": {"x_mm": -275.0, "y_mm": 0.0, "z_mm": -15.0, "yaw_deg": 0.0}}
        return r1, r2, {"x_mm": 0.0, "y_mm": 150.0, "z_mm": 150.0, "roll_deg": 90.0}, {}


TASK = PegInsertion()
"""The registry's entry (:data:`lfdt.tasks.registry.TASKS`)."""
