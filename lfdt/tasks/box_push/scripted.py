"""A scripted two-arm pusher: resolved-rate control of both end effectors straight towards the goal.

Used by the tests of the task's physics (coordination is needed: a slow or late arm turns the box)
and as a reference controller. Not an expert: it does not correct the box's yaw.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lfdt.tasks.box_push.env import BoxPushEnv, jacobian


@dataclass
class ScriptedPush:
    """Push with each end effector at its own speed along +y after its own delay, until the box reaches the goal."""

    speeds: tuple[float, float] = (0.08, 0.08)
    """End-effector speed of the slot-1 and slot-2 arm along +y, m/s (0 keeps that arm still)."""
    delays: tuple[float, float] = (0.0, 0.0)
    """Time before each arm starts moving, s."""
    lateral_gain: float = 2.0
    """Gain holding each end effector at its start x, 1/s."""
    stop_at_goal: bool = True
    """Stop both arms once the box centre has reached the goal's y."""

    def reset(self, env: BoxPushEnv) -> None:
        """Remember the start lateral positions of both end effectors."""
        self._x0 = [self._ee(env, i)[0] for i in range(2)]
        self._t = 0.0

    @staticmethod
    def _q_slices(env: BoxPushEnv) -> tuple[slice, slice]:
        n1, n2 = env.scene.nq_arm
        return slice(0, n1), slice(n1, n1 + n2)

    def _ee(self, env: BoxPushEnv, i: int) -> np.ndarray:
        from lfdt.tasks.box_push.env import forward_kinematics

        return forward_kinematics(env.scene.arms[i], env.data.qpos[self._q_slices(env)[i]])

    def action(self, env: BoxPushEnv) -> np.ndarray:
        """The torque command for the current state (advances the script's clock by one control step)."""
        box_y = env.data.qpos[env.scene.box_qpos][1]
        done = self.stop_at_goal and box_y >= env.cfg.box.goal[1]
        u = []
        for i, (arm, sl) in enumerate(zip(env.scene.arms, self._q_slices(env))):
            q = env.data.qpos[sl]
            ee = self._ee(env, i)
            vy = 0.0 if done or self._t < self.delays[i] else self.speeds[i]
            v = np.array([self.lateral_gain * (self._x0[i] - ee[0]), vy])
            qdot = np.linalg.pinv(jacobian(arm, q)) @ v
            # the arms are overdamped: a torque of damping * speed holds a joint speed
            u.append(np.asarray(arm.cfg.damping) * qdot / np.asarray(arm.cfg.gears))
        self._t += env.scene.dt
        return np.clip(np.concatenate(u), -1.0, 1.0)


def run_scripted(env: BoxPushEnv, script: ScriptedPush, seed: int | None = None, qpos: np.ndarray | None = None,
                 steps: int | None = None) -> dict:
    """Run one episode of a scripted push; returns the trajectory of box poses and the final info."""
    options = {"qpos": qpos} if qpos is not None else None
    obs, info = env.reset(seed=seed, options=options)
    script.reset(env)
    boxes, infos = [obs[-3:].copy()], [info]
    for _ in range(steps or env.cfg.max_episode_steps):
        obs, _, term, trunc, info = env.step(script.action(env))
        boxes.append(obs[-3:].copy())
        infos.append(info)
        if term or trunc:
            break
    return {"box": np.array(boxes), "infos": infos, "success": any(i["is_success"] for i in infos)}
