"""MuJoCo twin of the paper's two real tasks (§IV-E), at the level the real pipeline sees them.

The real pipeline observes end positions (the arms' by forward kinematics, the hand's and the object's
by AprilTags) and commands target end positions (turned into joint angles by our IK). The twin models
exactly that interface in each task's plane:

* **position-controlled arms**: each robot end effector follows its commanded target through a speed
  limit (``robot_speed``) and a first-order lag (position servo with damping), as the myCobot's servos do;
* **the human hand**: a free-floating body with a larger, round contact shape, pulled by a soft weld towards
  where the (scripted) person moves it, faster and noisier than a robot, and holding the object with a
  different grasp than a gripper does;
* ``block_push`` (horizontal plane x-y): the two ends push an elongated block onto a line; pushing at
  different speeds turns it;
* ``peg_insertion`` (vertical plane x-z): Robot1 holds a slotted receptacle, Robot2 holds a peg; the peg
  must enter the slot; the object is the peg (its pose is observed), held with some compliance.

States use :data:`BLOCK_PUSH` / :data:`PEG_INSERTION` layouts (2 numbers per arm, 3 for the object);
actions are target end positions relative to the current ones (2 per arm: where to go next, the same
information as the real pipeline's target position, in a form that behaviour cloning learns well).
Domains Y, R1H and HR2 as in the simulated experiment.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium import spaces

from lfdt import layout
from lfdt.layout import TaskLayout

TASKS = ("block_push", "peg_insertion")
BLOCK_GOAL_LINE = 0.22
"""y of the line the block must be pushed onto, m."""


def _task_layout(name: str, axes: tuple[str, str], angle: str) -> TaskLayout:
    arms = ("r1", "r2", "h")
    pos = {a: [f"{a}.{axes[0]}", f"{a}.{axes[1]}"] for a in arms}
    return TaskLayout(name, pos, {a: [f"{a}.d{axes[0]}", f"{a}.d{axes[1]}"] for a in arms},
                      [f"obj.{axes[0]}", f"obj.{axes[1]}", f"obj.{angle}"], pos)


BLOCK_PUSH = _task_layout("block_push", ("x", "y"), "yaw")
PEG_INSERTION = _task_layout("peg_insertion", ("x", "z"), "pitch")
LAYOUTS: dict[str, TaskLayout] = {"block_push": BLOCK_PUSH, "peg_insertion": PEG_INSERTION}


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
        if task not in TASKS:
            raise ValueError(f"unknown twin task {task!r}; expected one of {TASKS}")
        if domain not in layout.DOMAINS:
            raise ValueError(f"unknown domain {domain!r}; expected one of {layout.DOMAINS}")
        self.task, self.domain, self.cfg = task, domain, cfg or TwinConfig()
        self.layout = LAYOUTS[task]
        self.arms = layout.DOMAIN_ARMS[domain]
        self.model = mujoco.MjModel.from_xml_string(_scene_xml(task, self.arms, self.cfg))
        self.data = mujoco.MjData(self.model)
        self.frame_skip = round(self.cfg.control_dt / self.cfg.timestep)
        self.observation_space = spaces.Box(-np.inf, np.inf, shape=(7,), dtype=np.float64)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(4,), dtype=np.float64)
        self.render_mode, self._size, self._renderer = render_mode, size, None
        self._axes = (0, 1) if task == "block_push" else (0, 2)
        self._setpoints = np.zeros((2, 2))
        self._steps = 0
        g = self._geometry()
        self.workspace = g["workspace"]

    # ---------------------------------------------------------------- geometry of each task
    def _geometry(self) -> dict:
        if self.task == "block_push":
            return {"workspace": np.array([[-0.18, 0.02], [0.18, 0.30]]), "goal": BLOCK_GOAL_LINE}
        return {"workspace": np.array([[-0.20, 0.05], [0.20, 0.25]]), "depth": 0.025}

    def _body_xy(self, name: str) -> np.ndarray:
        return self.data.body(name).xpos[list(self._axes)].copy()

    def _object_pose(self) -> np.ndarray:
        obj = self.data.body("obj")
        quat = obj.xquat
        if self.task == "block_push":
            angle = 2 * math.atan2(quat[3], quat[0])  # rotation about z
        else:
            angle = 2 * math.atan2(quat[2], quat[0])  # rotation about y
        angle = (angle + math.pi) % (2 * math.pi) - math.pi
        return np.array([*obj.xpos[list(self._axes)], angle])

    def observe(self) -> np.ndarray:
        """[slot-1 end (2), slot-2 end (2), object pose (3)]; the hand's position for the human slot."""
        ends = [self._body_xy("hand" if a == "h" else f"ee{i + 1}") for i, a in enumerate(self.arms)]
        return np.concatenate([*ends, self._object_pose()])

    # ---------------------------------------------------------------- reset and step
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        rng = self.np_random
        mujoco.mj_resetData(self.model, self.data)
        if self.task == "block_push":
            bx, by, yaw = rng.uniform(-0.01, 0.01), 0.12 + rng.uniform(-0.01, 0.01), rng.uniform(-0.05, 0.05)
            self._set_object(bx, by, yaw)
            back = np.array([math.sin(yaw), -math.cos(yaw)])
            side = np.array([math.cos(yaw), math.sin(yaw)])
            starts = [np.array([bx, by]) + s * 0.05 * side + 0.032 * back + rng.normal(0, 0.002, 2) for s in (-1, 1)]
        else:
            hole = np.array([0.15, 0.15]) + rng.uniform(-0.02, 0.02, 2)
            peg_hand = np.array([-0.12, 0.15]) + rng.uniform(-0.02, 0.02, 2)
            starts = [hole, peg_hand]
        for i, a in enumerate(self.arms):
            self._place(i, a, starts[i])
        self._setpoints = np.array(starts)
        mujoco.mj_forward(self.model, self.data)
        if self.task == "peg_insertion":
            self._settle_peg()
        self._steps = 0
        return self.observe(), self._info()

    def _set_object(self, a: float, b: float, angle: float) -> None:
        if self.task == "block_push":
            for name, v in (("obj_x", a), ("obj_y", b), ("obj_yaw", angle)):
                self.data.qpos[self.model.jnt_qposadr[self.model.joint(name).id]] = v
            return
        qadr = self.model.jnt_qposadr[self.model.joint("obj_free").id]
        pos = np.zeros(3)
        pos[list(self._axes)] = (a, b)
        axis = 3 if self.task == "block_push" else 2
        quat = np.array([math.cos(angle / 2), 0.0, 0.0, 0.0])
        quat[axis] = math.sin(angle / 2)
        self.data.qpos[qadr:qadr + 7] = [*pos, *quat]

    def _place(self, slot: int, arm: str, p: np.ndarray) -> None:
        if arm == "h":
            pos = np.zeros(3)
            pos[list(self._axes)] = p
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

    def _settle_peg(self) -> None:
        """Let the compliant grasp of the peg settle before the episode starts."""
        for _ in range(200):
            mujoco.mj_step(self.model, self.data)
        self.data.qvel[:] = 0.0
        mujoco.mj_forward(self.model, self.data)

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
                pos[list(self._axes)] = self._setpoints[i] + tremor
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
        pose = self._object_pose()
        if self.task == "block_push":
            g = self._geometry()["goal"]
            speed = float(np.hypot(*(self.data.qvel[self.model.jnt_dofadr[self.model.joint(n).id]]
                                     for n in ("obj_x", "obj_y"))))
            ok = abs(pose[1] - g) < 0.012 and abs(pose[2]) < 0.08 and speed < 0.01
            return {"is_success": bool(ok), "line_error": float(pose[1] - g), "yaw": float(pose[2])}
        tip = self.data.site("peg_tip").xpos[[0, 2]]
        mouth = self.data.site("slot_mouth").xpos[[0, 2]]
        depth = float(tip[0] - mouth[0])
        ok = depth > self._geometry()["depth"] and abs(tip[1] - mouth[1]) < 0.006 and abs(pose[2]) < 0.12
        return {"is_success": bool(ok), "depth": depth, "height_error": float(tip[1] - mouth[1])}

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


# -------------------------------------------------------------------- scene description

def _scene_xml(task: str, arms: tuple[str, str], cfg: TwinConfig) -> str:
    horizontal = task == "block_push"
    ax_a, ax_b = ("1 0 0", "0 1 0") if horizontal else ("1 0 0", "0 0 1")
    kp = 2000.0  # stiff position servos: a pushing partner barely deflects them
    damp = kp * cfg.robot_lag  # first-order lag: damping / stiffness = time constant
    robot_colour = {"r1": "0.25 0.45 0.85 1", "r2": "0.85 0.45 0.2 1"}
    bodies = []
    actuators = []
    for i, arm in enumerate(arms):
        slot = i + 1
        if arm == "h":
            hand = '<geom name="hand" type="sphere" size="0.02" rgba="0.9 0.75 0.6 1" mass="0.3"/>'
            if not horizontal:
                hand += _held_part(task, slot, human=True)
            bodies.append(f'<body name="hand"><freejoint name="hand_free"/>{hand}</body>')
            continue
        finger = (f'<geom type="cylinder" size="0.01 0.02" rgba="{robot_colour[arm]}" mass="0.2"/>' if horizontal
                  else f'<geom type="box" size="0.012 0.012 0.012" rgba="{robot_colour[arm]}" mass="0.2"/>')
        if not horizontal:
            finger += _held_part(task, slot, human=False)
        bodies.append(
            f'<body name="ee{slot}">'
            f'<joint name="ee{slot}_a" type="slide" axis="{ax_a}" damping="{damp}" armature="0.01"/>'
            f'<joint name="ee{slot}_b" type="slide" axis="{ax_b}" damping="{damp}" armature="0.01"/>'
            f'{finger}</body>')
        actuators += [f'<position name="ee{slot}_a" joint="ee{slot}_a" kp="{kp}"/>',
                      f'<position name="ee{slot}_b" joint="ee{slot}_b" kp="{kp}"/>']
    mocap = '<body name="hand_target" mocap="true"/>'
    weld = ('<weld body1="hand_target" body2="hand" solref="0.06 1"/>' if "h" in arms else "")
    if horizontal:
        # quasi-static: the block slides on viscous joints, a stand-in for table friction
        obj = ('<body name="obj">'
               '<joint name="obj_x" type="slide" axis="1 0 0" damping="4"/>'
               '<joint name="obj_y" type="slide" axis="0 1 0" damping="4"/>'
               '<joint name="obj_yaw" type="hinge" axis="0 0 1" damping="0.02"/>'
               '<geom type="box" size="0.08 0.015 0.015" mass="0.2" rgba="0.2 0.7 0.3 1"/></body>')
        extra = ('<geom type="box" size="0.2 0.002 0.001" pos="0 0.22 -0.02" rgba="0.1 0.6 0.1 1" '
                 'contype="0" conaffinity="0"/>')
        camera = '<camera name="view" pos="0 0.14 0.75" xyaxes="1 0 0 0 1 0" fovy="40"/>'
    else:
        obj, extra = _peg_body(arms), ""
        camera = '<camera name="view" pos="0 -0.75 0.15" xyaxes="1 0 0 0 0 1" fovy="40"/>'
    return f"""<mujoco model="lfdt_twin_{task}">
  <option timestep="{cfg.timestep}" gravity="0 0 0" integrator="implicitfast"/>
  <visual><global offwidth="480" offheight="480"/></visual>
  <worldbody>
    <light pos="0 0 1" dir="0 0 -1"/>
    {camera}
    {extra}
    {mocap}
    {''.join(bodies)}
    {obj}
  </worldbody>
  <equality>{weld}{_peg_grasp(arms) if not horizontal else ''}</equality>
  <actuator>{''.join(actuators)}</actuator>
</mujoco>"""


def _held_part(task: str, slot: int, human: bool) -> str:
    """What a slot holds in peg insertion: slot 1 the slotted receptacle (rigid in the hand or gripper)."""
    if slot != 1:
        return ""  # slot 2's peg is a separate, compliantly held body (the observed object)
    # held from behind its back wall, mouth facing -x; a person holds it further back and tilted
    off, tilt = (-0.095, 0.06) if human else (-0.085, 0.0)
    gap, t, length = 0.022, 0.006, 0.06
    plate = f'type="box" size="{length / 2} 0.015 {t / 2}" rgba="0.5 0.5 0.5 1" mass="0.05"'
    return (f'<body name="slot" pos="{off} 0 0" euler="0 {tilt} 0">'
            f'<geom {plate} pos="{length / 2} 0 {gap / 2 + t / 2}"/>'
            f'<geom {plate} pos="{length / 2} 0 {-gap / 2 - t / 2}"/>'
            f'<geom type="box" size="{t / 2} 0.015 {gap / 2 + t}" pos="{length + t / 2} 0 0" '
            f'rgba="0.5 0.5 0.5 1" mass="0.05"/>'
            f'<site name="slot_mouth" pos="0 0 0" size="0.003"/></body>')


def _peg_body(arms: tuple[str, str]) -> str:
    return ('<body name="obj" pos="0 0 0.15"><freejoint name="obj_free"/>'
            '<geom type="box" size="0.04 0.008 0.008" mass="0.05" rgba="0.2 0.7 0.3 1"/>'
            '<site name="peg_tip" pos="0.04 0 0" size="0.003"/></body>')


def _peg_grasp(arms: tuple[str, str]) -> str:
    """Slot 2 holds the peg compliantly: a gripper close to its rear end, a hand further back and tilted."""
    holder = "hand" if arms[1] == "h" else "ee2"
    if arms[1] == "h":
        rel = 'relpose="-0.065 0 0.0 0.9997 0 0.025 0"'  # peg centre 6.5 cm ahead of the hand, tilted ~3 deg
    else:
        rel = 'relpose="-0.05 0 0 1 0 0 0"'
    return f'<weld body1="obj" body2="{holder}" {rel} solref="0.01 1"/>'


# -------------------------------------------------------------------- scripted behaviour

PROGRAMMED_SPEED = 0.045
"""Speed of the robot's programmed demonstration motion, m/s."""
MEETING_POINT = np.array([0.12, 0.15])
"""Where the programmed robot brings the receptacle in peg insertion (R1H), m."""


class ProgrammedMotion:
    """The robot's motion programmed in advance for demonstrations (the same rule every time; only the start
    differs), as absolute targets of its end in the task plane, one per control step. Used by the twin and by
    ``python -m lfdt.robot record-demos`` on the real robots.

    block_push: push straight ahead (+y) at PROGRAMMED_SPEED until the block should be on the line.
    peg_insertion: slot 1 (receptacle) moves to MEETING_POINT and holds; slot 2 (peg) moves 8 cm ahead (+x).
    """

    def __init__(self, task: str, robot_slot: int, obs: np.ndarray, control_dt: float,
                 goal_line: float | None = None):
        self.task, self.dt = task, control_dt
        self.start = obs[2 * robot_slot:2 * robot_slot + 2].copy()
        if task == "block_push":
            self.waypoint = self.start + (0.0, (BLOCK_GOAL_LINE if goal_line is None else goal_line) - obs[5])
        else:
            self.waypoint = MEETING_POINT.copy() if robot_slot == 0 else self.start + (0.08, 0.0)
        self.t = 0

    def next_target(self) -> np.ndarray:
        """The target of the next control step (moves at the programmed speed, then stays at the waypoint)."""
        self.t += 1
        d = self.waypoint - self.start
        frac = min(PROGRAMMED_SPEED * self.dt * self.t / max(float(np.linalg.norm(d)), 1e-9), 1.0)
        return self.start + frac * d


class ScriptedDemo:
    """A demonstration in domain X: the robot replays a programmed motion, the (scripted) person adapts.

    block_push: the robot pushes its end of the block straight ahead at a programmed speed for a programmed
    distance; the person pushes the other end, keeping the block level by watching its yaw.
    peg_insertion: the robot either brings the receptacle to a programmed point and holds it (R1H) or moves
    the peg straight ahead at its height (HR2); the person aligns the peg with the slot, or the slot with the
    peg, and completes the insertion.
    """

    def __init__(self, env: TwinEnv):
        if env.domain == "Y":
            raise ValueError("scripted demonstrations are for domain X (R1H or HR2)")
        self.env = env
        self.robot_slot = 0 if env.domain == "R1H" else 1
        self.human_slot = 1 - self.robot_slot
        self.program = ProgrammedMotion(env.task, self.robot_slot, env.observe(), env.cfg.control_dt)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        act = np.zeros((2, 2))
        act[self.robot_slot] = self.program.next_target()
        act[self.human_slot] = self._human(obs)
        return (act - obs[:4].reshape(2, 2)).reshape(-1)  # targets relative to the ends

    def _human(self, obs: np.ndarray) -> np.ndarray:
        env = self.env
        hand = obs[2 * self.human_slot:2 * self.human_slot + 2]
        robot = obs[2 * self.robot_slot:2 * self.robot_slot + 2]
        reach = env.cfg.human_speed * env.cfg.control_dt
        if env.task == "block_push":
            yaw = obs[6]
            # keep the block level: the right end (slot 2) is ahead when yaw > 0, the left end when yaw < 0
            sign = 1.0 if self.human_slot == 1 else -1.0
            ahead = (robot[1] - 0.01 - hand[1]) - sign * 0.6 * yaw
            return hand + (0.0, float(np.clip(ahead, -reach, reach)))
        tip = env.data.site("peg_tip").xpos[[0, 2]]
        mouth = env.data.site("slot_mouth").xpos[[0, 2]]
        gap = mouth - tip  # > 0 in x while the tip is still outside the slot
        aligned = abs(gap[1]) < 0.003
        holds_peg = self.human_slot == 1
        # line up 1.5 cm in front of the slot, then insert to 3.5 cm depth; the person moves what it holds
        want_x = (gap[0] - 0.015) if not (aligned and gap[0] < 0.02) else (gap[0] + 0.035)
        step = np.array([want_x, gap[1]]) if holds_peg else -np.array([want_x, gap[1]])
        return hand + np.clip(step, -reach, reach)


def random_action(env: TwinEnv, rng: np.random.Generator, obs: np.ndarray, reach: float = 0.008) -> np.ndarray:
    """Random motion: each end's target a random offset of up to ``reach`` m (about one control step of travel,
    so that the motion still tells which target was sent), held for a few steps by the caller."""
    return rng.uniform(-reach, reach, size=4)


# -------------------------------------------------------------------- data generation and evaluation

def twin_schema(task: str, domain: str, kind: str, metadata: dict):
    """The Parquet schema of twin recordings (the same conventions as the simulated experiment's data)."""
    from lfdt import data

    tl = LAYOUTS[task]
    if kind == "random":
        actions = tl.action_columns(domain)
    else:
        actions = tl.arm_action_columns(layout.robot_arm(domain))
    return data.transitions_schema(tl.state_columns(domain), actions, metadata={
        "kind": kind, "task": task, "domain": domain, "layout": tl.describe(), **metadata})


def record_random(task: str, domain: str, samples: int, episode_steps: int, seed: int, out_dir,
                  cfg: TwinConfig | None = None, hold_max: int = 3) -> int:
    """Random motion in the twin: targets a random offset from each end, held 1..hold_max steps; per-episode files.

    Returns the number of transitions written.
    """
    from lfdt.robot.recording import EpisodeRecorder
    from lfdt.seeding import episode_seed

    env = TwinEnv(task, domain, cfg)
    rec = EpisodeRecorder(out_dir, twin_schema(task, domain, "random", {"seed": seed, "samples": samples}),
                          env.cfg.control_dt)
    written, ep = 0, 0
    while written < samples:
        rng = np.random.default_rng(episode_seed("random", seed, domain, ep))
        obs, _ = env.reset(seed=episode_seed("random", seed, domain, ep))
        rec.start()
        act, hold = None, 0
        for _ in range(min(episode_steps, samples - written)):
            if hold == 0:
                act, hold = random_action(env, rng, obs), int(rng.integers(1, hold_max + 1))
            nxt, *_ = env.step(act)
            rec.add(obs, act, nxt)
            obs, hold, written = nxt, hold - 1, written + 1
        rec.finish()
        ep += 1
    return written


def record_demos(task: str, pairing: str, n: int, seed: int, out_dir, cfg: TwinConfig | None = None,
                 max_attempts: int = 200) -> dict:
    """Scripted demonstrations in X (robot programmed, person adapting); only successful ones are kept."""
    from lfdt.robot.recording import EpisodeRecorder
    from lfdt.seeding import episode_seed

    env = TwinEnv(task, pairing, cfg)
    robot_slot = 0 if pairing == "R1H" else 1
    rec = EpisodeRecorder(out_dir, twin_schema(task, pairing, "demos", {"seed": seed, "demos": n}),
                          env.cfg.control_dt)
    kept, attempts, lengths = 0, 0, []
    while kept < n:
        if attempts >= max_attempts:
            raise RuntimeError(f"{task} {pairing}: {kept} successful demonstrations in {attempts} attempts")
        s = episode_seed("demos", seed, pairing, attempts)
        obs, _ = env.reset(seed=s)
        demo = ScriptedDemo(env)
        rec.start()
        success = False
        for _ in range(env.cfg.max_steps):
            act = demo(obs)
            nxt, _, term, trunc, _ = env.step(act)
            # the robot's action is its commanded target; the hand has no action (it is only tracked)
            rec.add(obs, act.reshape(2, 2)[robot_slot], nxt)
            obs = nxt
            if term or trunc:
                success = bool(term)
                break
        attempts += 1
        if success:
            lengths.append(len(rec._rows))
            rec.finish()
            kept += 1
        else:
            rec.abort()
    return {"demonstrations": kept, "attempts": attempts, "mean_length": float(np.mean(lengths)),
            "transitions": int(np.sum(lengths))}


def evaluate(task: str, policy, trials: int, cfg: TwinConfig | None = None, purpose: str = "evaluation",
             videos: int = 0, video_dir=None) -> list[dict]:
    """Trials of a policy in the twin's domain Y from fixed start states; per-trial success."""
    from lfdt.evaluation import rollout_trials

    def make_env(record: bool) -> TwinEnv:
        return TwinEnv(task, "Y", cfg, render_mode="rgb_array" if record else None)

    results = rollout_trials(policy, make_env, trials, videos, video_dir, purpose=purpose)
    for r in results:
        r.update({k: v for k, v in r.pop("final_info").items() if k != "is_success"})
    return results
