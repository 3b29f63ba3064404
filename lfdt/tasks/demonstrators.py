"""Who moves in a twin demonstration: the robot's motion programmed in advance and the (scripted) person.

The same rule runs on the real robots (``python -m lfdt.robot record-demos``) and in the twin; the task
(:mod:`lfdt.tasks`) says where the program goes and how the person adapts.
"""

from __future__ import annotations

import numpy as np

from lfdt import layout
from lfdt.tasks import registry
from lfdt.tasks.planar_env import TwinEnv

PROGRAMMED_SPEED = 0.045
"""Speed of the robot's programmed demonstration motion, m/s."""


class ProgrammedMotion:
    """The robot's motion programmed in advance for demonstrations (the same rule every time; only the start
    differs), as absolute targets of its end in the task plane, one per control step: towards the task's
    waypoint at PROGRAMMED_SPEED, then holding it."""

    def __init__(self, task: str, robot_slot: int, obs: np.ndarray, control_dt: float,
                 goal_line: float | None = None):
        self.task, self.dt = task, control_dt
        self.start = obs[2 * robot_slot:2 * robot_slot + 2].copy()
        self.waypoint = registry.get(task).program_waypoint(robot_slot, self.start, obs, goal_line)
        self.t = 0

    def next_target(self) -> np.ndarray:
        """The target of the next control step (moves at the programmed speed, then stays at the waypoint)."""
        self.t += 1
        d = self.waypoint - self.start
        frac = min(PROGRAMMED_SPEED * self.dt * self.t / max(float(np.linalg.norm(d)), 1e-9), 1.0)
        return self.start + frac * d


class TwinDemonstrator:
    """A demonstration in domain X: the robot replays its programmed motion, the scripted person adapts
    (:meth:`lfdt.tasks.base.PlanarTask.person_target`). Called with an observation, it returns both slots'
    targets relative to their ends."""

    def __init__(self, env: TwinEnv):
        if env.domain == "Y":
            raise ValueError("scripted demonstrations are for domain X (R1H or HR2)")
        self.env = env
        self.robot_slot = layout.DOMAIN_ARMS[env.domain].index(layout.robot_arm(env.domain))
        self.human_slot = 1 - self.robot_slot
        self.program = ProgrammedMotion(env.task, self.robot_slot, env.observe(), env.cfg.control_dt)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        act = np.zeros((2, 2))
        act[self.robot_slot] = self.program.next_target()
        act[self.human_slot] = self.env.task_def.person_target(self.env, self.human_slot, self.robot_slot, obs)
        return (act - obs[:4].reshape(2, 2)).reshape(-1)  # targets relative to the ends
