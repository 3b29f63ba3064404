"""Block push (the paper's first real task, §IV-E): two ends push an elongated block onto a line on the table.

Horizontal plane (x, y). Pushing the two ends at different speeds turns the block; it must arrive on the line
level (small yaw) and at rest.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from lfdt.tasks.base import PlanarTask

if TYPE_CHECKING:
    from lfdt.tasks.planar_env import TwinEnv

GOAL_LINE = 0.22
"""y of the line the block must be pushed onto, m."""
RANDOM_MOTION_ADVANCE = 0.10
"""A random-motion episode starts with the block and both ends moved forward (+y) by up to this much, m."""


class BlockPush(PlanarTask):
    """The block push in the twin's horizontal plane."""

    name = "block_push"
    plane = ("x", "y")
    angle = "yaw"
    angle_axis = "z"
    workspace = np.array([[-0.18, 0.02], [0.18, 0.30]])

    def arm_geom(self, slot: int, colour: str) -> str:
        """A round pusher (a vertical cylinder)."""
        return f'<geom type="cylinder" size="0.01 0.02" rgba="{colour}" mass="0.2"/>'

    def object_xml(self, arms: tuple[str, str]) -> str:
        """The block on viscous slide joints (quasi-static: a stand-in for table friction)."""
        return ('<body name="obj">'
                '<joint name="obj_x" type="slide" axis="1 0 0" damping="4"/>'
                '<joint name="obj_y" type="slide" axis="0 1 0" damping="4"/>'
                '<joint name="obj_yaw" type="hinge" axis="0 0 1" damping="0.02"/>'
                '<geom type="box" size="0.08 0.015 0.015" mass="0.2" rgba="0.2 0.7 0.3 1"/></body>')

    def extra_xml(self) -> str:
        """The goal line."""
        return (f'<geom type="box" size="0.2 0.002 0.001" pos="0 {GOAL_LINE:g} -0.02" rgba="0.1 0.6 0.1 1" '
                'contype="0" conaffinity="0"/>')

    def camera_xml(self) -> str:
        """Looking down on the table."""
        return '<camera name="view" pos="0 0.14 0.75" xyaxes="1 0 0 0 1 0" fovy="40"/>'

    def reset(self, env: TwinEnv, rng: np.random.Generator) -> list[np.ndarray]:
        """The block near (0, 0.12) with a small yaw; each end 5 cm from its centre, just behind it."""
        bx, by, yaw = rng.uniform(-0.01, 0.01), 0.12 + rng.uniform(-0.01, 0.01), rng.uniform(-0.05, 0.05)
        for joint, v in (("obj_x", bx), ("obj_y", by), ("obj_yaw", yaw)):
            env.data.qpos[env.model.jnt_qposadr[env.model.joint(joint).id]] = v
        back = np.array([math.sin(yaw), -math.cos(yaw)])
        side = np.array([math.cos(yaw), math.sin(yaw)])
        return [np.array([bx, by]) + s * 0.05 * side + 0.032 * back + rng.normal(0, 0.002, 2) for s in (-1, 1)]

    def random_motion_start(self, env: TwinEnv, rng: np.random.Generator) -> list[np.ndarray]:
        """The start state moved forward along the push by U(0, RANDOM_MOTION_ADVANCE): from the start state alone
        random motion covered the ends up to y = 0.14 m, the demonstrations push them to 0.20 m (README, twin
        development)."""
        starts = self.reset(env, rng)
        advance = rng.uniform(0.0, RANDOM_MOTION_ADVANCE)
        env.data.qpos[env.model.jnt_qposadr[env.model.joint("obj_y").id]] += advance
        return [s + np.array([0.0, advance]) for s in starts]

    def info(self, env: TwinEnv) -> dict[str, Any]:
        """Success: the block within 12 mm of the line, |yaw| < 0.08 rad, slower than 1 cm/s."""
        pose = env.object_pose()
        speed = float(np.hypot(*(env.data.qvel[env.model.jnt_dofadr[env.model.joint(n).id]]
                                 for n in ("obj_x", "obj_y"))))
        ok = abs(pose[1] - GOAL_LINE) < 0.012 and abs(pose[2]) < 0.08 and speed < 0.01
        return {"is_success": bool(ok), "line_error": float(pose[1] - GOAL_LINE), "yaw": float(pose[2])}

    def program_waypoint(self, robot_slot: int, start: np.ndarray, obs: np.ndarray,
                         goal_line: float | None = None) -> np.ndarray:
        """Straight ahead (+y) by the block's distance to the line, measured before the take."""
        return start + (0.0, (GOAL_LINE if goal_line is None else goal_line) - obs[5])

    def person_target(self, env: TwinEnv, human_slot: int, robot_slot: int, obs: np.ndarray) -> np.ndarray:
        """Push the other end level with the robot's, correcting by the block's yaw."""
        hand = obs[2 * human_slot:2 * human_slot + 2]
        robot = obs[2 * robot_slot:2 * robot_slot + 2]
        reach = env.cfg.human_speed * env.cfg.control_dt
        yaw = obs[6]
        # keep the block level: the right end (slot 2) is ahead when yaw > 0, the left end when yaw < 0
        sign = 1.0 if human_slot == 1 else -1.0
        ahead = (robot[1] - 0.01 - hand[1]) - sign * 0.6 * yaw
        return hand + (0.0, float(np.clip(ahead, -reach, reach)))

    def example_rig(self) -> tuple[dict, dict, dict, dict]:
        """Both arms behind the block facing +y (yaw 90: the arm's forward is world +y; its flange plane
        z = 100 mm sweeps y 95..175 mm); the table tag lies beyond the line."""
        r1 = {"port": "/dev/ttyUSB0", "base": {"x_mm": -60.0, "y_mm": -55.0, "z_mm": 0.0, "yaw_deg": 90.0},
              "workspace_min_mm": [140.0, -50.0, 90.0], "workspace_max_mm": [240.0, 90.0, 110.0]}
        r2 = {"port": "/dev/ttyUSB1", "base": {"x_mm": 60.0, "y_mm": -55.0, "z_mm": 0.0, "yaw_deg": 90.0},
              "workspace_min_mm": [140.0, -90.0, 90.0], "workspace_max_mm": [240.0, 50.0, 110.0]}
        return r1, r2, {"x_mm": 0.0, "y_mm": 300.0, "z_mm": 0.0}, {"goal_line_m": 0.20}


TASK = BlockPush()
"""The registry's entry (:data:`lfdt.tasks.registry.TASKS`)."""
