"""Random-motion data: batched MuJoCo rollouts of random torque commands.

The distribution: each episode starts from the task's start distribution (the same as the
experts'), with the box moved a further U[0, box_y_spread] along the push direction so that the
data covers the whole path to the goal (box poses out of an arm's reach are drawn again); then
every joint receives a command drawn uniformly from [-amplitude, amplitude], held for a number
of control steps drawn uniformly from {hold_min, ..., hold_max} (independently per episode and
per hold). Holding a command lets the heavily damped arms actually travel, so the data covers
the workspace and the box gets pushed, not only jittered.

Simulation goes through ``mujoco.rollout`` on all threads: the controls of a whole batch of
episodes are drawn first (open loop), then MuJoCo steps them in C. The resulting states are the
same as stepping :class:`lfdt.tasks.box_push.env.BoxPushEnv` (``tests/test_random_motion.py``).
"""

from __future__ import annotations

import time
from collections.abc import Callable

import mujoco
import mujoco.rollout
import numpy as np
import pyarrow as pa

from lfdt import data
from lfdt.config import EnvConfig, RandomConfig
from lfdt.seeding import episode_seed
from lfdt.tasks.box_push import columns as box_columns
from lfdt.tasks.box_push.env import BoxPushModel, jacobian


def random_commands(rng: np.random.Generator, steps: int, act_dim: int, cfg: RandomConfig) -> np.ndarray:
    """A (steps, act_dim) sequence of held uniform commands."""
    out = np.empty((steps, act_dim))
    t = 0
    while t < steps:
        hold = int(rng.integers(cfg.hold_min, cfg.hold_max + 1))
        out[t:t + hold] = rng.uniform(-cfg.amplitude, cfg.amplitude, size=act_dim)
        t += hold
    return out


PUSH_SPEED = (0.02, 0.12)
"""Range of a pushing episode's end speed along the push direction per arm, m/s (the robot's top speed is ~0.12)."""
PUSH_SIDEWAYS = 0.03
"""Half-range of its sideways end speed, m/s."""
PUSH_DELAY = (0.0, 1.0)
"""Range of the time before an arm starts pushing, s."""
PUSH_DISTANCE = (0.02, 0.2)
"""Range of how far an arm's end travels before it holds, m."""


def push_commands(scene: BoxPushModel, qpos0: np.ndarray, rng: np.random.Generator, steps: int,
                  cfg: RandomConfig) -> np.ndarray:
    """A (steps, act_dim) open-loop push: per arm, the torques that move its end along +y (and a little sideways) at a
    random speed after a random delay for a random distance along its unloaded kinematic path (an overdamped joint
    holds a speed ``gear * command / damping``), then hold; held uniform commands of ``cfg.push_noise`` on top. The
    arms' speeds, starts and distances are drawn independently, so the box is pushed in step and out of it."""
    dt = scene.dt
    n1, n2 = scene.nq_arm
    out = np.zeros((steps, scene.act_dim))
    for arm, sl in zip(scene.arms, (slice(0, n1), slice(n1, n1 + n2))):
        v = np.array([rng.uniform(-PUSH_SIDEWAYS, PUSH_SIDEWAYS), rng.uniform(*PUSH_SPEED)])
        start = int(round(rng.uniform(*PUSH_DELAY) / dt))
        moving = int(round(rng.uniform(*PUSH_DISTANCE) / (np.linalg.norm(v) * dt)))
        q = np.array(qpos0[sl], dtype=float)
        gear, damping = np.asarray(arm.cfg.gears), np.asarray(arm.cfg.damping)
        limit = np.asarray(arm.cfg.joint_range)
        for t in range(start, min(steps, start + moving)):
            qdot = np.linalg.pinv(jacobian(arm, q)) @ v
            out[t, sl] = damping * qdot / gear
            q = np.clip(q + qdot * dt, -limit, limit)
    if cfg.push_noise > 0:
        out += random_commands(rng, steps, scene.act_dim, cfg.model_copy(update={"amplitude": cfg.push_noise}))
    return np.clip(out, -1.0, 1.0)


def episode_commands(scene: BoxPushModel, qpos0: np.ndarray, rng: np.random.Generator, cfg: RandomConfig
                     ) -> np.ndarray:
    """One episode's commands: a push with probability ``cfg.push_fraction``, else held uniform commands."""
    if cfg.push_fraction > 0 and rng.uniform() < cfg.push_fraction:
        return push_commands(scene, qpos0, rng, cfg.episode_steps, cfg)
    return random_commands(rng, cfg.episode_steps, scene.act_dim, cfg)


def reachable_start(scene: BoxPushModel, rng: np.random.Generator, y_spread: float,
                    tries: int = 100) -> np.ndarray:
    """A start with the box up to ``y_spread`` further along; draws again where an arm cannot reach the box
    (far along the path the shorter human stand-in can run out of reach)."""
    for _ in range(tries):
        try:
            return scene.sample_initial_qpos(rng, y_spread)
        except ValueError:
            continue
    raise ValueError(f"no reachable start in {tries} draws with random.box_y_spread = {y_spread}")


def initial_physics_state(scene: BoxPushModel, data_: mujoco.MjData, qpos: np.ndarray) -> np.ndarray:
    """The full physics state vector of a configuration at rest."""
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    mujoco.mj_resetData(scene.model, data_)
    data_.qpos[:] = qpos
    mujoco.mj_forward(scene.model, data_)
    state = np.empty(mujoco.mj_stateSize(scene.model, spec))
    mujoco.mj_getState(scene.model, data_, state, spec)
    return state


def rollout_episodes(scene: BoxPushModel, qpos0: np.ndarray, actions: np.ndarray, threads: int = 1
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Simulate episodes open loop. qpos0 (B, nq), actions (B, T, nu) -> states (B, T+1, obs_dim) and qvel.

    Returns the observation sequence (including the start) and the box speed after each step.
    """
    model = scene.model
    nbatch, steps, _ = actions.shape
    datas = [mujoco.MjData(model) for _ in range(max(1, threads))]
    init = np.stack([initial_physics_state(scene, datas[0], q) for q in qpos0])
    control = np.repeat(actions, scene.cfg.frame_skip, axis=1)
    state, _ = mujoco.rollout.rollout(model, datas, init, control)
    # keep the state at the end of each control step; FULLPHYSICS = [time, qpos, qvel, ...]
    state = state[:, scene.cfg.frame_skip - 1::scene.cfg.frame_skip]
    nq, nv = model.nq, model.nv
    qpos = np.concatenate([qpos0[:, None, :], state[:, :, 1:1 + nq]], axis=1)
    qvel = np.concatenate([np.zeros((nbatch, 1, nv)), state[:, :, 1 + nq:1 + nq + nv]], axis=1)
    return scene.observe(qpos, qvel), qvel


def collect_random(domain: str, env_cfg: EnvConfig, cfg: RandomConfig,
                   progress: Callable[[int], None] | None = None) -> tuple[pa.Table, dict]:
    """Collect ``cfg.transitions`` random-motion transitions in ``domain``; returns the table and stats."""
    scene = BoxPushModel(domain, env_cfg)
    n_episodes = -(-cfg.transitions // cfg.episode_steps)
    state_cols = box_columns.state_columns(domain)
    schema = data.transitions_schema(
        state_cols, box_columns.action_columns(domain),
        metadata={
            "kind": "random", "domain": domain, "seed": cfg.seed, "layout": box_columns.describe(),
            "env": env_cfg.model_dump(), "random": cfg.model_dump(),
            "action_distribution": "uniform in [-amplitude, amplitude] per joint, held for "
                                   "U{hold_min..hold_max} control steps"
                                   + ("" if not cfg.push_fraction else "; a share push_fraction of the episodes "
                                      "push instead (lfdt.tasks.box_push.random_motion.push_commands)"),
            "description": f"random-motion transitions in domain {domain}",
        })
    tables = []
    t0 = time.perf_counter()
    done = 0
    for start in range(0, n_episodes, cfg.episodes_per_batch):
        batch = range(start, min(start + cfg.episodes_per_batch, n_episodes))
        qpos0, acts = [], []
        for ep in batch:
            rng = np.random.default_rng(episode_seed("random", cfg.seed, domain, ep))
            qpos0.append(reachable_start(scene, rng, cfg.box_y_spread))
            acts.append(episode_commands(scene, qpos0[-1], rng, cfg))
        obs, _ = rollout_episodes(scene, np.array(qpos0), np.array(acts), cfg.threads)
        b, t = len(batch), cfg.episode_steps
        tables.append(data.transitions_table(
            schema,
            episode_index=np.repeat(np.array(batch), t), frame_index=np.tile(np.arange(t), b), dt=scene.dt,
            states=obs[:, :-1].reshape(b * t, -1), actions=np.array(acts).reshape(b * t, -1),
            next_states=obs[:, 1:].reshape(b * t, -1)))
        done += b * t
        if progress:
            progress(b * t)
    wall = time.perf_counter() - t0
    table = pa.concat_tables(tables).slice(0, cfg.transitions)
    stats = {"transitions": table.num_rows, "episodes": n_episodes, "wall_s": wall,
             "transitions_per_s": done / wall, "physics_steps_per_s": done * env_cfg.frame_skip / wall}
    return table, stats


def push_probe(env_cfg: EnvConfig, episodes: int = 200, steps: int = 60, seed: int = 0
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two-arm pushes in Y for judging F where the demonstrations are (not training data): ``episodes`` pushes of
    :func:`push_commands` without added noise, from the task's start states of the 'diagnostics' seed block. Returns
    (states, actions, next states) in raw units."""
    scene = BoxPushModel("Y", env_cfg)
    cfg = RandomConfig(episode_steps=steps, push_fraction=1.0, push_noise=0.0)
    qpos0, acts = [], []
    for ep in range(episodes):
        rng = np.random.default_rng(episode_seed("diagnostics", seed, "Y", ep))
        qpos0.append(reachable_start(scene, rng, 0.0))
        acts.append(push_commands(scene, qpos0[-1], rng, steps, cfg))
    obs, _ = rollout_episodes(scene, np.array(qpos0), np.array(acts), 1)
    n = episodes * steps
    return (obs[:, :-1].reshape(n, -1).astype(np.float32), np.array(acts).reshape(n, -1).astype(np.float32),
            obs[:, 1:].reshape(n, -1).astype(np.float32))
