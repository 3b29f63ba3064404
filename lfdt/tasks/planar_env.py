"""MuJoCo twin of the paper's two real tasks (§IV-E), at the level the real pipeline sees them.

The real pipeline observes end positions (the arms' by forward kinematics, the hand's and the object's
by AprilTags) and commands target end positions (turned into joint angles by our IK). The twin models
exactly that interface in each task's plane:

* **position-controlled arms**: each robot end effector follows its commanded target through a speed
  limit (``robot_speed``) and a first-order lag (position servo with damping), as the myCobot's servos do;
* **the human hand**: a free-floating body with a larger, round contact shape, pulled by a soft weld towards
  where the (scripted) person moves it, faster and noisier than a robot, and holding the object with a
  different grasp than a gripper does;
* the task (:mod:`lfdt.tasks`) adds its object, what the ends hold, its start states and its success rule.

States use the task's layout (2 numbers per arm, 3 for the object); actions are target end positions relative
to the current ones (2 per arm: where to go next, the same information as the real pipeline's target position,
in a form that behaviour cloning learns well). Domains Y, R1H and HR2 as in the simulated experiment.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium import spaces

from lfdt import layout
from lfdt.tasks import registry

if TYPE_CHECKING:  # the task interface makes this environment (PlanarTask.make_env): for the hints only
    from lfdt.tasks.base import PlanarTask


@dataclass(frozen=True)
class TwinConfig:
    """Physical parameters of the twin (metres, seconds)."""

    control_dt: float = 0.1
    """Control period (the real loop runs at about 10 Hz: tracking, IK, send_angles)."""
    timestep: float = 0.002
    """Physics step."""
    robot_speed: float = 0.06
    """Speed limit of a robot end effector, m/s."""
    robot_lag: float = 0.08
    """Time constant of a robot end effector following its setpoint, s."""
    human_speed: float = 0.12
    """Speed limit of the human hand, m/s (a person moves faster than the small servo arm)."""
    human_noise: float = 0.001
    """Standard deviation of the hand's tremor per control step, m."""
    max_steps: int = 40
    """Control steps per episode."""


class TwinEnv(gym.Env):
    """One task of the twin in one domain. Action: target end positions of both slots (4 numbers)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, task: str, domain: str, cfg: TwinConfig | None = None, render_mode: str | None = None,
                 size: int = 240):
        if domain not in layout.DOMAINS:
            raise ValueError(f"unknown domain {domain!r}; expected one of {layout.DOMAINS}")
        self.task_def: PlanarTask = registry.get(task)
        self.task, self.domain, self.cfg = task, domain, cfg or TwinConfig()
        self.layout = self.task_def.layout
        self.arms = layout.DOMAIN_ARMS[domain]
        self.model = mujoco.MjModel.from_xml_string(scene_xml(self.task_def, self.arms, self.cfg))
        self.data = mujoco.MjData(self.model)
        self.frame_skip = round(self.cfg.control_dt / self.cfg.timestep)
        self.observation_space = spaces.Box(-np.inf, np.inf, shape=(7,), dtype=np.float64)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(4,), dtype=np.float64)
        self.render_mode, self._size, self._renderer = render_mode, size, None
        self._axes = list(self.task_def.axes)
        self._setpoints = np.zeros((2, 2))
        self._steps = 0
        self.workspace = self.task_def.workspace

    # ---------------------------------------------------------------- observation
    def _body_xy(self, name: str) -> np.ndarray:
        return self.data.body(name).xpos[self._axes].copy()

    def object_pose(self) -> np.ndarray:
        """The object's position in the task plane and its in-plane angle."""
        obj = self.data.body("obj")
        return np.array([*obj.xpos[self._axes], self.task_def.plane_angle(obj.xquat)])

    def observe(self) -> np.ndarray:
        """[slot-1 end (2), slot-2 end (2), object pose (3)]; the hand's position for the human slot."""
        ends = [self._body_xy("hand" if a == "h" else f"ee{i + 1}") for i, a in enumerate(self.arms)]
        return np.concatenate([*ends, self.object_pose()])

    # ---------------------------------------------------------------- reset and step
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        mujoco.mj_resetData(self.model, self.data)
        # options {"random_motion": True}: the task's start of a random-motion episode
        start = self.task_def.random_motion_start if (options or {}).get("random_motion") else self.task_def.reset
        starts = start(self, self.np_random)
        for i, a in enumerate(self.arms):
            self._place(i, a, starts[i])
        self._setpoints = np.array(starts)
        mujoco.mj_forward(self.model, self.data)
        self.task_def.settle(self)
        self._steps = 0
        return self.observe(), self._info()

    def _place(self, slot: int, arm: str, p: np.ndarray) -> None:
        if arm == "h":
            pos = np.zeros(3)
            pos[self._axes] = p
            qadr = self.model.jnt_qposadr[self.model.joint("hand_free").id]
            self.data.qpos[qadr:qadr + 7] = [*pos, 1, 0, 0, 0]
            self.data.mocap_pos[0] = pos
        else:
            for k, ax in enumerate(("a", "b")):
                self.data.qpos[self.model.jnt_qposadr[self.model.joint(f"ee{slot + 1}_{ax}").id]] = p[k]
            self._command(slot, p)

    def _command(self, slot: int, p: np.ndarray) -> None:
        for k, ax in enumerate(("a", "b")):
            self.data.ctrl[self.model.actuator(f"ee{slot + 1}_{ax}").id] = p[k]

    def step(self, action):
        # an action is each end's target relative to where the end is now (m); the target is kept in the workspace
        ends = self.observe()[:4].reshape(2, 2)
        a = np.clip(ends + np.asarray(action, dtype=float).reshape(2, 2), self.workspace[0], self.workspace[1])
        for i, arm in enumerate(self.arms):
            speed = self.cfg.human_speed if arm == "h" else self.cfg.robot_speed
            delta = a[i] - self._setpoints[i]
            dist = float(np.linalg.norm(delta))
            max_step = speed * self.cfg.control_dt
            self._setpoints[i] = a[i] if dist <= max_step else self._setpoints[i] + delta * (max_step / dist)
            if arm == "h":
                tremor = self.np_random.normal(0.0, self.cfg.human_noise, 2)
                pos = np.zeros(3)
                pos[self._axes] = self._setpoints[i] + tremor
                self.data.mocap_pos[0] = pos
            else:
                self._command(i, self._setpoints[i])
        mujoco.mj_step(self.model, self.data, nstep=self.frame_skip)
        self._steps += 1
        info = self._info()
        terminated = info["is_success"]
        truncated = self._steps >= self.cfg.max_steps and not terminated
        return self.observe(), float(terminated), terminated, truncated, info

    def _info(self) -> dict:
        return self.task_def.info(self)

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        if self._renderer is None:
            self._renderer = mujoco.Renderer(self.model, self._size, self._size)
        self._renderer.update_scene(self.data, camera="view")
        return self._renderer.render()

    def close(self):
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


def scene_xml(task: PlanarTask, arms: tuple[str, str], cfg: TwinConfig) -> str:
    """The MJCF of a task's scene in a domain: the two ends (robots on two slide joints in the plane, or the
    person's hand welded to a mocap target), what they hold, the object, the camera."""
    ax_a, ax_b = (" ".join("1" if c == axis else "0" for c in "xyz") for axis in task.plane)
    kp = 2000.0  # stiff position servos: a pushing partner barely deflects them
    damp = kp * cfg.robot_lag  # first-order lag: damping / stiffness = time constant
    robot_colour = {"r1": "0.25 0.45 0.85 1", "r2": "0.85 0.45 0.2 1"}
    bodies = []
    actuators = []
    for i, arm in enumerate(arms):
        slot = i + 1
        if arm == "h":
            hand = '<geom name="hand" type="sphere" size="0.02" rgba="0.9 0.75 0.6 1" mass="0.3"/>'
            hand += task.held_part(slot, human=True)
            bodies.append(f'<body name="hand"><freejoint name="hand_free"/>{hand}</body>')
            continue
        finger = task.arm_geom(slot, robot_colour[arm]) + task.held_part(slot, human=False)
        bodies.append(
            f'<body name="ee{slot}">'
            f'<joint name="ee{slot}_a" type="slide" axis="{ax_a}" damping="{damp}" armature="0.01"/>'
            f'<joint name="ee{slot}_b" type="slide" axis="{ax_b}" damping="{damp}" armature="0.01"/>'
            f'{finger}</body>')
        actuators += [f'<position name="ee{slot}_a" joint="ee{slot}_a" kp="{kp}"/>',
                      f'<position name="ee{slot}_b" joint="ee{slot}_b" kp="{kp}"/>']
    mocap = '<body name="hand_target" mocap="true"/>'
    weld = ('<weld body1="hand_target" body2="hand" solref="0.06 1"/>' if "h" in arms else "")
    return f"""<mujoco model="lfdt_twin_{task.name}">
  <option timestep="{cfg.timestep}" gravity="0 0 0" integrator="implicitfast"/>
  <visual><global offwidth="480" offheight="480"/></visual>
  <worldbody>
    <light pos="0 0 1" dir="0 0 -1"/>
    {task.camera_xml()}
    {task.extra_xml()}
    {mocap}
    {''.join(bodies)}
    {task.object_xml(arms)}
  </worldbody>
  <equality>{weld}{task.equality_xml(arms)}</equality>
  <actuator>{''.join(actuators)}</actuator>
</mujoco>"""
