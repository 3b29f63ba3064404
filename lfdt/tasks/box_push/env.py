"""MuJoCo "2D dual-arm box push" (paper Fig. 3(a), §IV-A) in three domains.

* ``Y``   : Robot1 and Robot2, both 3-link torque-controlled planar arms (deployment).
* ``R1H`` : Robot1 and the 4-link human stand-in where Robot2 would be (demonstrations).
* ``HR2`` : the human stand-in where Robot1 would be, and Robot2 (demonstrations).

The plane is seen from above (no gravity). The arms are heavily damped, so a torque command
sets a joint *speed* (gear / damping at full command) rather than an acceleration, and the box
slides on viscous joints that stop it within ~0.1 s once nothing pushes it: the task is
quasi-static. Success needs the box centre near the goal, its yaw small *and* the box at rest,
so an expert cannot slam it through the goal, and one arm pushing faster than the other turns
the box instead of moving it.

The observation layout is :mod:`lfdt.tasks.box_push.columns`. Observations are computed from joint positions and
velocities by :func:`observe` (planar forward kinematics), so the Gymnasium path and the
batched ``mujoco.rollout`` path used for random-motion collection produce identical states.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium import spaces

from lfdt import layout
from lfdt.config import ArmConfig, EnvConfig
from lfdt.tasks.box_push import columns as box_columns

if TYPE_CHECKING:  # only for hints: the environment itself does not need pandas
    import pandas as pd

ENV_IDS: dict[str, str] = {d: f"lfdt/BoxPush-{d}-v0" for d in layout.DOMAINS}


@dataclass(frozen=True)
class ArmSpec:
    """One arm placed in the scene."""

    name: str
    """Layout name: 'r1', 'r2' or 'h'."""
    slot: int
    """1 (left, Robot1's place) or 2 (right, Robot2's place)."""
    cfg: ArmConfig
    """Its links, motors and joint dynamics."""
    base: tuple[float, float]
    """Base position in the world, m."""

    @property
    def n(self) -> int:
        return len(self.cfg.links)

    @property
    def elbow_sign(self) -> float:
        """Elbows bend outwards (away from the other arm): left arm -1, right arm +1."""
        return -1.0 if self.slot == 1 else 1.0


def arm_specs(domain: str, cfg: EnvConfig) -> tuple[ArmSpec, ArmSpec]:
    """The two arms of a domain, in slot order."""
    if domain not in layout.DOMAINS:
        raise ValueError(f"unknown domain {domain!r}; expected one of {layout.DOMAINS}")
    a1, a2 = layout.DOMAIN_ARMS[domain]
    return (
        ArmSpec(a1, 1, cfg.human if a1 == "h" else cfg.robot, (-cfg.base_x, 0.0)),
        ArmSpec(a2, 2, cfg.human if a2 == "h" else cfg.robot, (cfg.base_x, 0.0)),
    )


# ----------------------------------------------------------------------------- kinematics

def forward_kinematics(arm: ArmSpec, q: np.ndarray) -> np.ndarray:
    """End position (..., 2) of an arm for joint angles q (..., n). Angle 0 points along +y."""
    links = np.asarray(arm.cfg.links)
    phi = np.cumsum(q, axis=-1)
    x = arm.base[0] - np.sum(links * np.sin(phi), axis=-1)
    y = arm.base[1] + np.sum(links * np.cos(phi), axis=-1)
    return np.stack([x, y], axis=-1)


def jacobian(arm: ArmSpec, q: np.ndarray) -> np.ndarray:
    """2 x n Jacobian of the end position with respect to the joint angles."""
    links = np.asarray(arm.cfg.links)
    phi = np.cumsum(q)
    dx = -links * np.cos(phi)
    dy = -links * np.sin(phi)
    # joint j moves every link from j outwards
    return np.stack([np.cumsum(dx[::-1])[::-1], np.cumsum(dy[::-1])[::-1]])


def inverse_kinematics(arm: ArmSpec, target: np.ndarray, tip_heading: float, bend: float = 0.0) -> np.ndarray:
    """Joint angles that put the end at ``target`` with the distal links pointing along ``tip_heading``.

    The redundancy of a 3- or 4-link arm is fixed by the headings of the distal links: the last link
    points along ``tip_heading``, a 4-link arm's third link along ``tip_heading + bend``. The first two
    joints then solve a 2-link problem with the elbow bent outwards (away from the other arm).
    Raises ValueError when the target is out of reach.
    """
    links = arm.cfg.links
    headings = [tip_heading] * (arm.n - 2)
    if arm.n >= 4:
        headings[0] = tip_heading + bend
    wrist = np.asarray(target, dtype=float).copy()
    for length, h in zip(links[2:], headings):
        wrist -= length * np.array([-math.sin(h), math.cos(h)])
    dx, dy = wrist[0] - arm.base[0], wrist[1] - arm.base[1]
    l1, l2 = links[0], links[1]
    c2 = (dx * dx + dy * dy - l1 * l1 - l2 * l2) / (2 * l1 * l2)
    if not -1.0 <= c2 <= 1.0:
        raise ValueError(f"{arm.name}: target {target} out of reach")
    q2 = arm.elbow_sign * math.acos(c2)
    alpha = math.atan2(-dx, dy)
    q1 = alpha - math.atan2(l2 * math.sin(q2), l1 + l2 * math.cos(q2))
    q = [q1, q2]
    prev = q1 + q2
    for h in headings:
        q.append(h - prev)
        prev = h
    return np.array([_wrap(a) for a in q])


_BENDS = np.linspace(-1.5, 1.5, 61)


def start_pose(arm: ArmSpec, target: np.ndarray, tip_heading: float) -> np.ndarray:
    """IK for a start pose; a 4-link arm takes the third-link heading that keeps its joints farthest from limits."""
    if arm.n < 4:
        return inverse_kinematics(arm, target, tip_heading)
    limits = np.asarray(arm.cfg.joint_range)
    best, best_margin = None, -np.inf
    for bend in _BENDS:
        try:
            q = inverse_kinematics(arm, target, tip_heading, float(bend))
        except ValueError:
            continue
        margin = float(np.min((limits - np.abs(q)) / limits))
        if margin > best_margin:
            best, best_margin = q, margin
    if best is None:
        raise ValueError(f"{arm.name}: target {target} out of reach")
    return best


def contact_targets(arms: tuple[ArmSpec, ArmSpec], cfg: EnvConfig, box_pose: np.ndarray) -> np.ndarray:
    """Where each arm's end effector centre is when it touches its contact point on the box's rear face (2, 2)."""
    x, y, yaw = box_pose
    c, s = math.cos(yaw), math.sin(yaw)
    out = np.zeros((2, 2))
    for i, arm in enumerate(arms):
        lx = (-1 if arm.slot == 1 else 1) * cfg.contact_x
        ly = -cfg.box.size[1] / 2 - arm.cfg.tip_radius
        out[i] = (x + c * lx - s * ly, y + s * lx + c * ly)
    return out


def check_start_reachable(cfg: EnvConfig) -> None:
    """Both arms of every domain reach their start poses at the corners and the middle of the start distribution
    (the box's position +- start_noise_xy, its yaw +- start_noise_yaw); a StageError naming the keys otherwise, where
    the environment would fail at whichever reset first drew such a start, deep inside a stage (the preflight
    stage's check)."""
    from lfdt.errors import StageError

    b = cfg.box
    n, n_yaw = b.start_noise_xy, b.start_noise_yaw
    poses = [np.array([b.start[0] + dx, b.start[1] + dy, yaw])
             for dx in (-n, 0.0, n) for dy in (-n, 0.0, n) for yaw in (-n_yaw, 0.0, n_yaw)]
    for domain in layout.DOMAINS:
        arms = arm_specs(domain, cfg)
        for pose in poses:
            back = np.array([-math.sin(pose[2]), math.cos(pose[2])])  # as sample_initial_qpos places the ends
            try:
                for arm, target in zip(arms, contact_targets(arms, cfg, pose)):
                    start_pose(arm, target - cfg.start_gap * back, pose[2])
            except ValueError as err:
                raise StageError(f"params.yaml env: in domain {domain}, {err} at the start with the box at x = "
                                 f"{pose[0]:.3f} m, y = {pose[1]:.3f} m, yaw {pose[2]:.2f} rad; move env.box.start "
                                 "closer, narrow its start_noise_xy / start_noise_yaw, or change env.base_x or the "
                                 "arms' links") from None


def _wrap(a: float | np.ndarray) -> float | np.ndarray:
    """Angle(s) wrapped into [-pi, pi)."""
    if isinstance(a, np.ndarray):
        return (a + np.pi) % (2 * np.pi) - np.pi
    return (a + math.pi) % (2 * math.pi) - math.pi


# ----------------------------------------------------------------------------- model

def build_xml(domain: str, cfg: EnvConfig) -> str:
    """MJCF of the scene of one domain. Arms collide with the box, never with each other."""
    arms = arm_specs(domain, cfg)
    colours = {"r1": "0.25 0.45 0.85 1", "r2": "0.85 0.45 0.2 1", "h": "0.9 0.75 0.6 1"}
    bodies, actuators = [], []
    for arm in arms:
        c = arm.cfg
        xml = f'<body name="{arm.name}_base" pos="{arm.base[0]} {arm.base[1]} 0">\n'
        xml += '<geom type="cylinder" size="0.025 0.01" rgba="0.3 0.3 0.3 1" contype="0" conaffinity="0"/>\n'
        closing = ""
        for i, length in enumerate(c.links):
            pos = "0 0 0" if i == 0 else f"0 {c.links[i - 1]} 0"
            xml += (f'<body name="{arm.name}_link{i}" pos="{pos}">'
                    f'<joint name="{arm.name}_j{i}" type="hinge" axis="0 0 1" limited="true" '
                    f'range="{-c.joint_range[i]} {c.joint_range[i]}" damping="{c.damping[i]}" armature="{c.armature}"/>'
                    f'<geom type="capsule" fromto="0 0 0 0 {length} 0" size="{c.radius}" rgba="{colours[arm.name]}" '
                    f'contype="2" conaffinity="1" friction="{cfg.friction} 0.005 0.0001" density="500"/>\n')
            closing += "</body>"
            actuators.append(f'<motor name="{arm.name}_m{i}" joint="{arm.name}_j{i}" gear="{c.gears[i]}" '
                             f'ctrlrange="-1 1" ctrllimited="true"/>')
        xml += (f'<site name="{arm.name}_tip" pos="0 {c.links[-1]} 0" size="0.004"/>'
                f'<geom name="{arm.name}_hand" type="sphere" pos="0 {c.links[-1]} 0" size="{c.tip_radius}" '
                f'rgba="{colours[arm.name]}" contype="2" conaffinity="1" friction="{cfg.friction} 0.005 0.0001" '
                f'density="500"/>')
        xml += closing + "</body>\n"
        bodies.append(xml)
    b = cfg.box
    gx, gy = b.goal
    return f"""<mujoco model="lfdt_box_push_{domain}">
  <compiler angle="radian"/>
  <option timestep="{cfg.timestep}" gravity="0 0 0" integrator="implicitfast"/>
  <visual><global offwidth="640" offheight="640"/><quality shadowsize="0"/></visual>
  <worldbody>
    <light pos="0 0.2 1.5" dir="0 0 -1" castshadow="false"/>
    <camera name="top" pos="0 0.2 0.9" xyaxes="1 0 0 0 1 0" fovy="45"/>
    <geom type="plane" size="0.5 0.5 0.01" pos="0 0.2 -0.03" rgba="0.92 0.92 0.9 1" contype="0" conaffinity="0"/>
    <site name="goal" type="box" pos="{gx} {gy} -0.025" size="{b.size[0] / 2} {b.size[1] / 2} 0.001"
          rgba="0.1 0.1 0.1 0.5"/>
    {''.join(bodies)}
    <body name="box" pos="0 0 0">
      <joint name="box_x" type="slide" axis="1 0 0" damping="{b.slide_damping}"/>
      <joint name="box_y" type="slide" axis="0 1 0" damping="{b.slide_damping}"/>
      <joint name="box_yaw" type="hinge" axis="0 0 1" damping="{b.yaw_damping}"/>
      <geom name="box" type="box" size="{b.size[0] / 2} {b.size[1] / 2} 0.02" mass="{b.mass}" rgba="0.2 0.7 0.3 1"
            contype="1" conaffinity="2" friction="{cfg.friction} 0.005 0.0001"/>
    </body>
  </worldbody>
  <actuator>{''.join(actuators)}</actuator>
</mujoco>"""


class BoxPushModel:
    """A compiled scene of one domain plus the vectorised maps between MuJoCo state and observations."""

    def __init__(self, domain: str, cfg: EnvConfig):
        self.domain = domain
        self.cfg = cfg
        self.arms = arm_specs(domain, cfg)
        self.model = mujoco.MjModel.from_xml_string(build_xml(domain, cfg))
        n1, n2 = self.arms[0].n, self.arms[1].n
        self.nq_arm = (n1, n2)
        self.box_qpos = slice(n1 + n2, n1 + n2 + 3)
        self.obs_dim = len(box_columns.state_columns(domain))
        self.act_dim = n1 + n2
        self.dt = cfg.timestep * cfg.frame_skip
        assert self.model.nq == n1 + n2 + 3 and self.model.nu == self.act_dim

    def observe(self, qpos: np.ndarray, qvel: np.ndarray) -> np.ndarray:
        """Observations (..., obs_dim) from joint positions and velocities (..., nq)."""
        n1, n2 = self.nq_arm
        parts = []
        for arm, sl in zip(self.arms, (slice(0, n1), slice(n1, n1 + n2))):
            q = qpos[..., sl]
            parts += [q, qvel[..., sl], forward_kinematics(arm, q)]
        box = qpos[..., self.box_qpos].copy()
        box[..., 2] = _wrap(box[..., 2])
        parts.append(box)
        return np.concatenate(parts, axis=-1).astype(np.float64)

    def contact_targets(self, box_pose: np.ndarray) -> np.ndarray:
        """Where each end effector's centre is when it touches its contact point on the box's rear face (2, 2)."""
        return contact_targets(self.arms, self.cfg, box_pose)

    def sample_initial_qpos(self, rng: np.random.Generator, y_spread: float = 0.0) -> np.ndarray:
        """A start configuration: noisy box pose, end effectors just behind the box's rear face, noisy joints.

        ``y_spread`` > 0 moves the box a further U[0, y_spread] along the push direction (random-motion
        data uses it to cover the whole path to the goal, not only the start).
        """
        b = self.cfg.box
        extra_y = rng.uniform(0, y_spread) if y_spread else 0.0
        box = np.array([
            b.start[0] + rng.uniform(-b.start_noise_xy, b.start_noise_xy),
            b.start[1] + rng.uniform(-b.start_noise_xy, b.start_noise_xy) + extra_y,
            rng.uniform(-b.start_noise_yaw, b.start_noise_yaw),
        ])
        targets = self.contact_targets(box)
        back = np.array([-math.sin(box[2]), math.cos(box[2])])
        qs = []
        for arm, target in zip(self.arms, targets):
            # each arm's pose, then its noise: an arm out of reach ends the draw with the first arm's noise drawn
            # (random motion draws again, and its data depend on that order)
            q = start_pose(arm, target - self.cfg.start_gap * back, box[2])
            q = q + rng.uniform(-self.cfg.joint_noise, self.cfg.joint_noise, size=arm.n)
            qs.append(np.clip(q, -np.asarray(arm.cfg.joint_range), np.asarray(arm.cfg.joint_range)))
        return np.concatenate(qs + [box])

    def success(self, box_pose: np.ndarray, box_speed: float | np.ndarray) -> bool | np.ndarray:
        """Success: near the goal, small yaw and at rest, all at once."""
        s = self.cfg.success
        dist = np.hypot(box_pose[..., 0] - self.cfg.box.goal[0], box_pose[..., 1] - self.cfg.box.goal[1])
        return (dist < s.distance) & (np.abs(_wrap(box_pose[..., 2])) < s.yaw) & (box_speed < s.speed)

    def path_yaw_limit(self, start_yaw: float | np.ndarray) -> float | np.ndarray:
        """The most |yaw| the path rule allows along an episode that started at ``start_yaw``: the start's own
        |yaw| or the end-state rule's threshold, whichever is larger, plus ``success.path_yaw_margin``."""
        s = self.cfg.success
        return np.maximum(np.abs(_wrap(start_yaw)), s.yaw) + s.path_yaw_margin


class BoxPushEnv(gym.Env):
    """Gymnasium environment of one domain of the box push. Torque actions in [-1, 1] per joint."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 20}

    def __init__(self, domain: str = "Y", config: EnvConfig | dict | None = None,
                 render_mode: str | None = None, width: int = 480, height: int = 480,
                 scene: BoxPushModel | None = None):
        cfg = config if isinstance(config, EnvConfig) else EnvConfig.model_validate(config or {})
        self.cfg = cfg
        self.domain = domain
        # many environments of one domain (a batched evaluation) can share one compiled scene
        self.scene = scene if scene is not None else BoxPushModel(domain, cfg)
        self.model = self.scene.model
        self.data = mujoco.MjData(self.model)
        self.metadata = {**self.metadata, "render_fps": round(1 / self.scene.dt)}
        self.observation_space = spaces.Box(-np.inf, np.inf, shape=(self.scene.obs_dim,), dtype=np.float64)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(self.scene.act_dim,), dtype=np.float32)
        self.render_mode = render_mode
        self._renderer: mujoco.Renderer | None = None
        self._size = (height, width)
        self._steps = 0
        self._yaw_limit = math.inf
        self._max_abs_yaw = 0.0

    # -- state helpers
    def set_state(self, qpos: np.ndarray, qvel: np.ndarray | None = None) -> np.ndarray:
        """Put the simulation in a given configuration (velocities zero unless given); returns the observation."""
        mujoco.mj_resetData(self.model, self.data)
        self.data.qpos[:] = qpos
        self.data.qvel[:] = 0.0 if qvel is None else qvel
        mujoco.mj_forward(self.model, self.data)
        self._steps = 0
        start_yaw = float(self.data.qpos[self.scene.box_qpos][2])
        self._yaw_limit = float(self.scene.path_yaw_limit(start_yaw))
        self._max_abs_yaw = abs(float(_wrap(start_yaw)))
        return self._obs()

    def _obs(self) -> np.ndarray:
        return self.scene.observe(self.data.qpos.copy(), self.data.qvel.copy())

    def _info(self) -> dict:
        sl = self.scene.box_qpos
        box = self.data.qpos[sl].copy()
        box[2] = _wrap(float(box[2]))
        speed = float(np.hypot(*self.data.qvel[sl][:2]))
        goal = np.asarray(self.cfg.box.goal)
        ee = [forward_kinematics(arm, self.data.qpos[s]) for arm, s in zip(
            self.scene.arms, (slice(0, self.scene.nq_arm[0]), slice(self.scene.nq_arm[0], sum(self.scene.nq_arm))))]
        targets = self.scene.contact_targets(box)
        self._max_abs_yaw = max(self._max_abs_yaw, abs(float(box[2])))
        success = bool(self.scene.success(box, speed))
        return {
            "is_success": success,
            # the end-state rule and, along the way so far, the path rule (SuccessConfig.path_yaw_margin)
            "is_path_success": success and self._max_abs_yaw <= self._yaw_limit,
            "max_abs_yaw": self._max_abs_yaw,
            "box_distance": float(np.linalg.norm(box[:2] - goal)),
            "box_yaw": float(box[2]),
            "box_speed": speed,
            "contact_distance": [float(np.linalg.norm(e - t)) for e, t in zip(ee, targets)],
        }

    # -- gymnasium API
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        if options and "qpos" in options:
            qpos = np.asarray(options["qpos"], dtype=float)
        else:
            qpos = self.scene.sample_initial_qpos(self.np_random)
        obs = self.set_state(qpos)
        return obs, self._info()

    def step(self, action):
        a = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
        da = a - self.data.ctrl  # the command held since the last step (zero after a reset)
        self.data.ctrl[:] = a
        mujoco.mj_step(self.model, self.data, nstep=self.cfg.frame_skip)
        self._steps += 1
        obs = self._obs()
        info = self._info()
        r = self.cfg.reward
        reward = (-r.w_box * info["box_distance"] - r.w_yaw * abs(info["box_yaw"])
                  - r.w_contact * sum(info["contact_distance"]) - r.w_action * float(a @ a)
                  - r.w_action_rate * float(da @ da))
        terminated = info["is_success"]
        if terminated:
            reward += r.success_bonus
        truncated = self._steps >= self.cfg.max_episode_steps and not terminated
        return obs, float(reward), terminated, truncated, info

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        if self._renderer is None:
            self._renderer = mujoco.Renderer(self.model, *self._size)
        self._renderer.update_scene(self.data, camera="top")
        return self._renderer.render()

    def close(self):
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


def replay_check(df: pd.DataFrame, env_cfg: EnvConfig) -> dict:
    """Replay each translated demonstration's action labels in the real Y environment from its first state.

    Returns how far the replayed box ends from the translated box's final pose (mean position error in m,
    mean absolute yaw error in rad) and how often the replay solves the task: a physical-consistency check.
    """
    env = BoxPushEnv("Y", env_cfg)
    cols = box_columns.state_columns("Y")
    q_cols = [c for c in cols if ".q" in c]
    dq_cols = [c for c in cols if ".dq" in c]
    a_cols = [layout.ACTION_PREFIX + c for c in box_columns.action_columns("Y")]
    pos_err, yaw_err, solved = [], [], []
    for _, g in df.groupby("episode_index", sort=True):
        g = g.sort_values("frame_index")
        first = g.iloc[0]
        qpos = np.concatenate([[first[layout.STATE_PREFIX + c] for c in q_cols],
                               [first[layout.STATE_PREFIX + c] for c in box_columns.OBJECT_COLUMNS]])
        qvel = np.concatenate([[first[layout.STATE_PREFIX + c] for c in dq_cols], np.zeros(3)])
        env.reset(seed=0)
        env.set_state(qpos, qvel)
        success = False
        for a in g[a_cols].to_numpy():
            _, _, term, _, info = env.step(a)
            success = success or term
        final = env.data.qpos[env.scene.box_qpos]
        target = g.iloc[-1][[layout.NEXT_STATE_PREFIX + c for c in box_columns.OBJECT_COLUMNS]].to_numpy(float)
        pos_err.append(float(np.linalg.norm(final[:2] - target[:2])))
        yaw_err.append(float(abs((final[2] - target[2] + np.pi) % (2 * np.pi) - np.pi)))
        solved.append(success)
    return {"replay_box_position_error_m": float(np.mean(pos_err)), "replay_box_yaw_error_rad": float(np.mean(yaw_err)),
            "replay_success_rate": float(np.mean(solved)), "replayed_demos": len(pos_err)}


def register_envs() -> None:
    """Register the three domains with Gymnasium (idempotent)."""
    for domain, env_id in ENV_IDS.items():
        if env_id not in gym.registry:
            gym.register(id=env_id, entry_point="lfdt.tasks.box_push.env:BoxPushEnv", kwargs={"domain": domain})


register_envs()
