"""The robot's side of a demonstration under the paper's protocol: a motion programmed in advance.

In the paper's demonstrations "the robotic arm replays a motion programmed in advance instead of
real-time teleoperation" (§IV-E) and the human adapts to it (§I, Fig. 1). Here each robot has a
program of its own (:class:`lfdt.config.RobotProgramConfig`: a nominal push speed, start time and end
point, made without regard to the other robot's). A *take* draws the per-demonstration variation
(speed scale, start delay, lateral offset, push-length offset; :class:`lfdt.config.ProgramVariation`)
once, before the episode, from the start scene and a random generator; during the episode the
controller reads only the clock and the robot's own joint angles. It never reads the box, the human
or the other arm.

The controller is resolved-rate control of the end effector: hold the take's lateral position,
advance along the push direction (+y) at the take's speed after its delay for the box's start-to-goal
distance (measured before the take), then hold. Pushing both sides of the box the same length keeps its
yaw: the program does not straighten the box, the human must. The arms are overdamped, so a torque of
``damping * qdot / gear`` holds a joint speed ``qdot``.
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from lfdt import layout
from lfdt.config import EnvConfig, ProgramConfig, RobotProgramConfig
from lfdt.tasks.box_push.env import ArmSpec, BoxPushEnv, arm_specs, forward_kinematics, jacobian


@dataclass(frozen=True)
class Take:
    """One replay of a robot's program: everything is fixed before the episode starts."""

    speed: float
    """End-effector push speed along +y, m/s."""
    delay: float
    """Time before the push starts, s."""
    x: float
    """Lateral end-effector position held during the take, m (world frame)."""
    end_y: float
    """End-effector y at which the push stops and is held, m."""
    noise: float
    """Standard deviation of the Gaussian noise added to each torque command."""


def program_for(robot: str, cfg: ProgramConfig) -> RobotProgramConfig:
    """The program of Robot1 ('r1') or Robot2 ('r2')."""
    if robot not in ("r1", "r2"):
        raise ValueError(f"no program for arm {robot!r}; expected 'r1' or 'r2'")
    return cfg.r1 if robot == "r1" else cfg.r2


def draw_take(arm: ArmSpec, q0: np.ndarray, box0: np.ndarray, env_cfg: EnvConfig, program: RobotProgramConfig,
              cfg: ProgramConfig, rng: np.random.Generator) -> Take:
    """Draw one take of a robot's program from the start scene (its start pose ``q0``, the box's start pose
    ``box0``) and ``rng``.

    The push covers the start-to-goal distance of the box (as an operator measures it before the take), shifted
    by the program's own ``end_offset`` and the take's jitter. It does not correct the box's yaw.
    """
    ee0 = forward_kinematics(arm, np.asarray(q0, dtype=float))
    v = cfg.variation
    distance = env_cfg.box.goal[1] - float(box0[1])
    return Take(
        speed=program.speed * rng.uniform(*v.speed_scale),
        delay=program.delay + rng.uniform(0.0, v.delay),
        x=float(ee0[0]) + rng.uniform(-v.lateral_offset, v.lateral_offset),
        end_y=float(ee0[1]) + distance + program.end_offset + rng.uniform(-v.end_offset, v.end_offset),
        noise=v.action_noise,
    )


class ProgrammedRobot:
    """Replays one take of a robot's program on one arm; reads only time and the arm's own joint angles."""

    def __init__(self, arm: ArmSpec, take: Take, dt: float, lateral_gain: float, approach_gain: float,
                 rng: np.random.Generator):
        self.arm = arm
        self.take = take
        self.dt = dt
        self.lateral_gain = lateral_gain
        self.approach_gain = approach_gain
        self.rng = rng
        self.t = 0.0

    def action(self, q: np.ndarray) -> np.ndarray:
        """Normalised torque command for the arm's joint angles ``q``; advances the program's clock one step."""
        ee = forward_kinematics(self.arm, q)
        k = self.take
        if self.t < k.delay:
            vy = 0.0
        else:
            # advance at the take's speed, slowing down on the last millimetres so the end point is held
            vy = float(np.clip(self.approach_gain * (k.end_y - ee[1]), -k.speed, k.speed))
        v = np.array([self.lateral_gain * (k.x - ee[0]), vy])
        qdot = np.linalg.pinv(jacobian(self.arm, q)) @ v
        u = np.asarray(self.arm.cfg.damping) * qdot / np.asarray(self.arm.cfg.gears)
        if k.noise > 0:
            u = u + self.rng.normal(0.0, k.noise, size=u.shape)
        self.t += self.dt
        return np.clip(u, -1.0, 1.0)


def robot_slot(domain: str, robot: str, env_cfg: EnvConfig) -> tuple[int, ArmSpec]:
    """The slot index (0 or 1) and the placed arm of ``robot`` in ``domain``."""
    for i, arm in enumerate(arm_specs(domain, env_cfg)):
        if arm.name == robot:
            return i, arm
    raise ValueError(f"arm {robot!r} is not in domain {domain!r}")


def make_robot(domain: str, robot: str, q0: np.ndarray, box0: np.ndarray, env_cfg: EnvConfig, cfg: ProgramConfig,
               rng: np.random.Generator) -> ProgrammedRobot:
    """A programmed ``robot`` of ``domain`` for one take, drawn from the start scene (its joint angles ``q0``,
    the box's pose ``box0``)."""
    _, arm = robot_slot(domain, robot, env_cfg)
    take = draw_take(arm, q0, box0, env_cfg, program_for(robot, cfg), cfg, rng)
    return ProgrammedRobot(arm, take, env_cfg.timestep * env_cfg.frame_skip, cfg.lateral_gain, cfg.approach_gain, rng)


class ProgrammedPartnerEnv(gym.Env):
    """A demonstration pairing seen by the human stand-in: its robot replays a take of its program.

    The action is the human's joint torques only; the observation is the whole state of the pairing (the
    robot's included), as a person sees the robot beside them. Every reset draws a new take from the
    environment's random generator, so an SAC human trains against the distribution of programmed motions.
    ``info['robot_action']`` and ``info['action']`` give the robot's command and the full command of the step.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 20}

    def __init__(self, pairing: str, config: EnvConfig | dict | None = None,
                 program: ProgramConfig | dict | None = None, render_mode: str | None = None,
                 width: int = 480, height: int = 480):
        self.env = BoxPushEnv(pairing, config, render_mode=render_mode, width=width, height=height)
        self.cfg = self.env.cfg
        self.program = program if isinstance(program, ProgramConfig) else ProgramConfig.model_validate(program or {})
        self.pairing = pairing
        self.robot = layout.robot_arm(pairing)
        self.robot_slot, _ = robot_slot(pairing, self.robot, self.cfg)
        n1, n2 = self.env.scene.nq_arm
        self._slots = (slice(0, n1), slice(n1, n1 + n2))
        self._robot_q = self._slots[self.robot_slot]
        self._human = self._slots[1 - self.robot_slot]
        self.observation_space = self.env.observation_space
        n_h = self._human.stop - self._human.start
        self.action_space = spaces.Box(-1.0, 1.0, shape=(n_h,), dtype=np.float32)
        self.render_mode = render_mode
        self.metadata = self.env.metadata
        self.robot_program: ProgrammedRobot | None = None

    @property
    def scene(self):
        return self.env.scene

    @property
    def data(self):
        return self.env.data

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        obs, info = self.env.reset(seed=seed, options=options)
        qpos = self.env.data.qpos
        self.robot_program = make_robot(self.pairing, self.robot, qpos[self._robot_q].copy(),
                                        qpos[self.env.scene.box_qpos].copy(), self.cfg, self.program,
                                        self.env.np_random)
        return obs, info

    def step(self, action):
        human = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
        robot = self.robot_program.action(self.env.data.qpos[self._robot_q].copy())
        full = np.zeros(self.env.scene.act_dim)
        full[self._robot_q] = robot
        full[self._human] = human
        obs, reward, term, trunc, info = self.env.step(full)
        info = {**info, "robot_action": robot, "action": full}
        return obs, reward, term, trunc, info

    def render(self):
        return self.env.render()

    def close(self):
        self.env.close()


def programs_together_success(env_cfg: EnvConfig, cfg: ProgramConfig, episodes: int, seed_purpose: str = "development",
                              run_seed: int = 0) -> dict[str, float]:
    """Success of both robots replaying takes of their own programs together in Y, nobody adapting: the two pairings'
    robot halves run together, by the end-state rule (``end``) and the path rule (``path``).

    The protocol's premise is that this is low: otherwise replaying the programs would already solve the task, and
    BC without translation, which clones each robot's half alone, would need no translation to coordinate.
    """
    from lfdt.seeding import episode_seed

    env = BoxPushEnv("Y", env_cfg)
    n1, n2 = env.scene.nq_arm
    slots = (slice(0, n1), slice(n1, n1 + n2))
    wins = np.zeros(2)
    for i in range(episodes):
        env.reset(seed=episode_seed(seed_purpose, run_seed, "Y", i))
        qpos = env.data.qpos.copy()
        robots = [make_robot("Y", arm.name, qpos[sl].copy(), qpos[env.scene.box_qpos].copy(), env_cfg, cfg,
                             env.np_random) for arm, sl in zip(env.scene.arms, slots)]
        for _ in range(env_cfg.max_episode_steps):
            a = np.concatenate([r.action(env.data.qpos[sl].copy()) for r, sl in zip(robots, slots)])
            _, _, term, trunc, info = env.step(a)
            if term or trunc:
                break
        wins += (bool(term), bool(term) and info["is_path_success"])
    return {"end": float(wins[0] / episodes), "path": float(wins[1] / episodes)}
