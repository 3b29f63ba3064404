"""SAC experts in domain X, their resumable training, evaluation and demonstration collection.

Two demonstration protocols (``demos.protocol``):

* ``programmed_robot`` (the paper's, default): the pairing's robot replays a motion programmed in
  advance (:mod:`lfdt.tasks.box_push.programmed`) and one stable-baselines3 SAC policy controls only the human
  stand-in, seeing the whole state: the coordination lives in the human;
* ``joint_expert``: one SAC policy controls both arms of a pairing, so the robot's recorded actions
  are themselves coordinated.

Checkpoints (every ``checkpoint_every`` env steps) hold the SB3 parameters and optimiser states
(``torch.save`` of state dicts, read back with ``weights_only=True``) and the replay buffer as
``.npz`` arrays; no pickles. They live in ``checkpoints/experts/<pairing>/`` (git-ignored, not a
DVC output, so ``dvc repro`` does not delete them) and are keyed by a hash of the configuration:
an interrupted run with the same params resumes from the last one, a run with other params starts
afresh. They are removed once the final model is written.

The final expert is ``policy.pt`` (the SB3 policy's state dict) with ``config.json`` beside it
(the resolved configuration, in the manner of rl-baselines3-zoo).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pyarrow as pa
import torch
from stable_baselines3 import SAC
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv

from lfdt import data, layout
from lfdt.config import DemosConfig, EnvConfig, ExpertsConfig, ProgramConfig
from lfdt.errors import StageError
from lfdt.nets import pin_linear_layers
from lfdt.optim import Adam
from lfdt.seeding import episode_seed, seed_everything
from lfdt.tasks.box_push import columns as box_columns
from lfdt.tasks.box_push.env import BoxPushEnv
from lfdt.tasks.box_push.programmed import ProgrammedPartnerEnv

_BUFFER_FIELDS = ("observations", "next_observations", "actions", "rewards", "dones", "timeouts")


def protocol_doc(demos_cfg: DemosConfig) -> dict:
    """What of the demonstration config the expert depends on: the protocol and, for it, the robots' programs."""
    doc: dict = {"protocol": demos_cfg.protocol}
    if demos_cfg.protocol == "programmed_robot":
        doc["program"] = demos_cfg.program.model_dump()
    return doc


def config_hash(pairing: str, env_cfg: EnvConfig, cfg: ExpertsConfig, demos_cfg: DemosConfig) -> str:
    """Hash of everything that determines a training run (a checkpoint resumes only a run with the same hash)."""
    doc = json.dumps({"pairing": pairing, "env": env_cfg.model_dump(), "experts": cfg.model_dump(),
                      **protocol_doc(demos_cfg)}, sort_keys=True)
    return hashlib.sha256(doc.encode()).hexdigest()[:16]


def make_env(pairing: str, env_cfg: EnvConfig, demos_cfg: DemosConfig) -> BoxPushEnv | ProgrammedPartnerEnv:
    """The environment the expert of a pairing acts in: the human beside a programmed robot, or both arms."""
    if demos_cfg.protocol == "programmed_robot":
        return ProgrammedPartnerEnv(pairing, env_cfg, demos_cfg.program)
    return BoxPushEnv(pairing, env_cfg)


def make_vec_env(pairing: str, env_cfg: EnvConfig, demos_cfg: DemosConfig, n_envs: int, seed: int) -> DummyVecEnv:
    """n_envs Monitor-wrapped environments of a pairing, seeded from the expert-training seed block."""
    venv = DummyVecEnv([lambda: Monitor(make_env(pairing, env_cfg, demos_cfg), info_keywords=("is_success",))
                        for _ in range(n_envs)])
    venv.seed(episode_seed("expert_train", seed, pairing, 0))
    return venv


def build_sac(env, cfg: ExpertsConfig, buffer_size: int | None = None, device: str | torch.device = "cpu") -> SAC:
    """An SAC agent with the configured networks and optimiser settings, its networks on ``device``.

    Its linear layers and its optimisers are the project's (:func:`lfdt.nets.pin_linear_layers`,
    :func:`lfdt.optim.Adam`), so that a gradient step is the same bits on every CPU (:mod:`lfdt.numerics`)."""
    model = SAC(
        "MlpPolicy", env, learning_rate=cfg.learning_rate, buffer_size=buffer_size or cfg.buffer_size,
        learning_starts=cfg.learning_starts, batch_size=cfg.batch_size, gamma=cfg.gamma, train_freq=1,
        gradient_steps=cfg.gradient_steps, policy_kwargs={"net_arch": list(cfg.net_arch), "optimizer_class": Adam},
        seed=cfg.seed, device=device, verbose=0)
    pin_linear_layers(model.policy)
    # SB3 builds the entropy coefficient's optimiser itself, as torch's Adam
    model.ent_coef_optimizer = Adam([model.log_ent_coef], lr=model.lr_schedule(1))
    # Our callback keeps the curve; without a logger of its own, SB3 makes an empty SB3-<date> folder in /tmp on
    # every learn().
    model.set_logger(Logger(folder=None, output_formats=[]))
    return model


# ----------------------------------------------------------------------------- checkpoints

class Checkpoints:
    """Resumable checkpoints of one training run in a directory; the newest is named by ``latest.json``."""

    def __init__(self, root: Path, run_hash: str):
        self.root = Path(root)
        self.run_hash = run_hash

    def latest(self) -> Path | None:
        """The newest complete checkpoint of this run, or None."""
        pointer = self.root / "latest.json"
        if not pointer.exists():
            return None
        meta = json.loads(pointer.read_text())
        path = self.root / meta["dir"]
        if meta.get("hash") != self.run_hash or not (path / "params.pt").exists():
            return None
        return path

    def save(self, model: SAC, curve: list[dict] | None = None) -> Path:
        """Write a checkpoint (with the learning curve so far), then point ``latest.json`` at it (atomic), then drop
        older ones."""
        name = f"step-{model.num_timesteps:09d}"
        tmp = self.root / f".{name}.tmp"
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir(parents=True)
        torch.save({
            "params": model.get_parameters(),
            "log_ent_coef": model.log_ent_coef.detach().clone(),
            "num_timesteps": model.num_timesteps,
            "n_updates": model._n_updates,
            "episode_num": model._episode_num,
        }, tmp / "params.pt")
        buf = model.replay_buffer
        np.savez(tmp / "replay_buffer.npz", pos=buf.pos, full=buf.full,
                 **{f: getattr(buf, f) for f in _BUFFER_FIELDS})
        (tmp / "curve.json").write_text(json.dumps(curve or []))
        final = self.root / name
        shutil.rmtree(final, ignore_errors=True)
        os.replace(tmp, final)
        pointer_tmp = self.root / ".latest.json.tmp"
        pointer_tmp.write_text(json.dumps({"dir": name, "hash": self.run_hash, "num_timesteps": model.num_timesteps}))
        os.replace(pointer_tmp, self.root / "latest.json")
        for old in self.root.glob("step-*"):
            if old != final:
                shutil.rmtree(old, ignore_errors=True)
        return final

    def load(self, model: SAC, path: Path) -> list[dict]:
        """Restore parameters, optimiser states, entropy coefficient, counters and replay buffer; returns the
        learning curve up to the checkpoint."""
        ckpt = torch.load(path / "params.pt", weights_only=True, map_location="cpu")
        model.set_parameters(ckpt["params"], exact_match=True)
        with torch.no_grad():
            model.log_ent_coef.copy_(ckpt["log_ent_coef"])
        model.num_timesteps = int(ckpt["num_timesteps"])
        model._n_updates = int(ckpt["n_updates"])
        model._episode_num = int(ckpt["episode_num"])
        with np.load(path / "replay_buffer.npz", allow_pickle=False) as z:
            buf = model.replay_buffer
            for f in _BUFFER_FIELDS:
                getattr(buf, f)[...] = z[f]
            buf.pos = int(z["pos"])
            buf.full = bool(z["full"])
        curve = path / "curve.json"
        return json.loads(curve.read_text()) if curve.exists() else []

    def clear(self) -> None:
        """Remove every checkpoint (after the final model is safely written)."""
        shutil.rmtree(self.root, ignore_errors=True)


class TrainingCallback(BaseCallback):
    """Progress bar, periodic checkpoints and learning curves (batched to MLflow through ``log``)."""

    def __init__(self, cfg: ExpertsConfig, checkpoints: Checkpoints, log: Callable[[dict, int], None] | None,
                 progress=None):
        super().__init__()
        self.cfg = cfg
        self.checkpoints = checkpoints
        self.log = log
        self.progress = progress
        self.successes: list[float] = []
        self.returns: list[float] = []
        self.lengths: list[float] = []
        self.curve: list[dict] = []
        self._next_log = 0
        self._next_ckpt = 0
        self._t0 = time.perf_counter()
        self._steps0 = 0
        self._updates0 = 0

    def _on_training_start(self) -> None:
        n = self.model.num_timesteps
        self._next_log = (n // self.cfg.log_every + 1) * self.cfg.log_every
        self._next_ckpt = (n // self.cfg.checkpoint_every + 1) * self.cfg.checkpoint_every
        self._steps0, self._updates0 = n, self.model._n_updates
        self._t0 = time.perf_counter()

    def _on_step(self) -> bool:
        for info in self.locals["infos"]:
            ep = info.get("episode")
            if ep is not None:
                self.returns.append(ep["r"])
                self.lengths.append(ep["l"])
                self.successes.append(float(info.get("is_success", False)))
        n = self.model.num_timesteps
        if self.progress is not None:
            self.progress.update(self.model.get_env().num_envs)
        if n >= self._next_log:
            self._next_log += self.cfg.log_every
            wall = time.perf_counter() - self._t0
            point = {
                "train/success_rate_last100": float(np.mean(self.successes[-100:])) if self.successes else 0.0,
                "train/episode_return_last100": float(np.mean(self.returns[-100:])) if self.returns else 0.0,
                "train/episode_length_last100": float(np.mean(self.lengths[-100:])) if self.lengths else 0.0,
                "train/env_steps_per_s": (n - self._steps0) / max(wall, 1e-9),
                "train/gradient_steps_per_s": (self.model._n_updates - self._updates0) / max(wall, 1e-9),
                "train/ent_coef": float(torch.exp(self.model.log_ent_coef.detach()).item()),
            }
            self.curve.append({"timesteps": n, **point})
            if self.log:
                self.log(point, n)
            if hasattr(self.progress, "set_postfix"):
                self.progress.set_postfix(success=f"{point['train/success_rate_last100']:.2f}")
        if n >= self._next_ckpt:
            self._next_ckpt += self.cfg.checkpoint_every
            self.checkpoints.save(self.model, self.curve)
        return True


def train_expert(pairing: str, env_cfg: EnvConfig, cfg: ExpertsConfig, demos_cfg: DemosConfig, checkpoint_dir: Path,
                 log: Callable[[dict, int], None] | None = None, progress=None,
                 device: str | torch.device = "cpu") -> tuple[SAC, dict]:
    """Train (or resume training) the SAC expert of a pairing, its networks on ``device`` (the environments step
    on the CPU). Returns the model and timing stats."""
    torch.set_num_threads(cfg.torch_threads)
    seed_everything(cfg.seed)
    venv = make_vec_env(pairing, env_cfg, demos_cfg, cfg.n_envs, cfg.seed)
    model = build_sac(venv, cfg, device=device)
    checkpoints = Checkpoints(checkpoint_dir, config_hash(pairing, env_cfg, cfg, demos_cfg))
    resumed_from, curve = 0, []
    latest = checkpoints.latest()
    if latest is not None:
        curve = checkpoints.load(model, latest)
        resumed_from = model.num_timesteps
        print(f"{pairing}: resuming from checkpoint {latest} at step {resumed_from:,} of {cfg.total_timesteps:,} "
              "(an earlier run with the same params stopped there)", file=sys.stderr, flush=True)
    if progress is not None:
        progress.update(resumed_from)
    callback = TrainingCallback(cfg, checkpoints, log, progress)
    callback.curve = curve  # the points before the interruption stay in the curve
    t0 = time.perf_counter()
    updates0 = model._n_updates
    remaining = cfg.total_timesteps - model.num_timesteps
    if remaining > 0:
        model.learn(remaining, callback=callback, reset_num_timesteps=latest is None, progress_bar=False)
    wall = time.perf_counter() - t0
    stats = {
        "resumed_from_timesteps": resumed_from,
        "timesteps": int(model.num_timesteps),
        "wall_time_s": wall,
        "env_steps_per_s": (model.num_timesteps - resumed_from) / max(wall, 1e-9),
        "gradient_steps_per_s": (model._n_updates - updates0) / max(wall, 1e-9),
        "gradient_steps": int(model._n_updates),
        "curve": callback.curve,
    }
    venv.close()
    return model, stats


# ----------------------------------------------------------------------------- saved experts

def save_expert(model: SAC, out_dir: Path, pairing: str, env_cfg: EnvConfig, cfg: ExpertsConfig,
                demos_cfg: DemosConfig, extra: dict) -> None:
    """Write ``policy.pt`` (state dict) and ``config.json`` (resolved config) atomically into out_dir."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    tmp = out_dir / ".policy.pt.tmp"
    state = model.policy.state_dict()
    if model.device.type != "cpu":  # a machine without the training device loads it too
        state = {k: v.cpu() for k, v in state.items()}
    torch.save(state, tmp)
    os.replace(tmp, out_dir / "policy.pt")
    human_only = demos_cfg.protocol == "programmed_robot"
    config = {
        "pairing": pairing, "algorithm": "SAC (stable-baselines3)", "env_id": f"lfdt/BoxPush-{pairing}-v0",
        **protocol_doc(demos_cfg),
        "controls": "the human stand-in only (the robot replays its program)" if human_only else "both arms",
        "observation_columns": box_columns.state_columns(pairing),
        "action_columns": box_columns.arm_action_columns("h") if human_only else box_columns.action_columns(pairing),
        "env": env_cfg.model_dump(), "experts": cfg.model_dump(),
        "config_hash": config_hash(pairing, env_cfg, cfg, demos_cfg), **extra,
    }
    (out_dir / "config.json").write_text(json.dumps(config, indent=2))


def expert_demos_config(config: dict) -> DemosConfig:
    """The protocol (and programs) a saved expert was trained for, from its ``config.json``."""
    protocol = config.get("protocol", "joint_expert")
    program = ProgramConfig.model_validate(config["program"]) if "program" in config else ProgramConfig()
    return DemosConfig(protocol=protocol, program=program)


def load_expert(model_dir: Path) -> tuple[SAC, dict]:
    """Load a saved expert (weights_only) into a fresh SAC agent; returns it and its config."""
    model_dir = Path(model_dir)
    config = json.loads((model_dir / "config.json").read_text())
    env_cfg = EnvConfig.model_validate(config["env"])
    cfg = ExpertsConfig.model_validate(config["experts"])
    env = make_env(config["pairing"], env_cfg, expert_demos_config(config))
    model = build_sac(env, cfg, buffer_size=1)
    model.policy.load_state_dict(torch.load(model_dir / "policy.pt", weights_only=True, map_location="cpu"))
    model.policy.set_training_mode(False)
    return model, config


def run_episode(model: SAC, env: BoxPushEnv | ProgrammedPartnerEnv, seed: int, deterministic: bool = True) -> dict:
    """Roll out one episode; returns states, full actions (both arms), next states, success and length."""
    obs, _ = env.reset(seed=seed)
    states, actions, nexts, successes = [], [], [], []
    for _ in range(env.cfg.max_episode_steps):
        act, _ = model.predict(obs, deterministic=deterministic)
        nobs, _, term, trunc, info = env.step(act)
        states.append(obs)
        # the programmed robot's command comes from the environment, the expert's from the policy
        actions.append(info["action"] if "action" in info else np.clip(act, -1.0, 1.0))
        nexts.append(nobs)
        successes.append(info["is_success"])
        obs = nobs
        if term or trunc:
            break
    return {"states": np.array(states), "actions": np.array(actions), "next_states": np.array(nexts),
            "success": bool(successes[-1]), "length": len(states), "final_info": info}


def evaluate_expert(model: SAC, pairing: str, env_cfg: EnvConfig, demos_cfg: DemosConfig, episodes: int,
                    seed: int) -> dict:
    """Success rate over ``episodes`` start states from the expert-evaluation seed block (never seen in training)."""
    env = make_env(pairing, env_cfg, demos_cfg)
    results = [run_episode(model, env, episode_seed("expert_eval", seed, pairing, i)) for i in range(episodes)]
    succ = [r for r in results if r["success"]]
    return {
        "success_rate": len(succ) / episodes,
        "episodes": episodes,
        "mean_success_length": float(np.mean([r["length"] for r in succ])) if succ else None,
        "mean_final_box_distance": float(np.mean([r["final_info"]["box_distance"] for r in results])),
        "mean_final_abs_yaw": float(np.mean([abs(r["final_info"]["box_yaw"]) for r in results])),
    }


def collect_demos(model: SAC, pairing: str, env_cfg: EnvConfig, cfg: DemosConfig,
                  progress: Callable[[], None] | None = None) -> tuple[pa.Table, dict]:
    """Roll out the expert until ``cfg.per_pairing`` successful demonstrations; keep only those
    (every attempt if ``cfg.success_only`` is False).

    Raises RuntimeError if ``cfg.max_attempts`` attempts do not give enough.
    """
    env = make_env(pairing, env_cfg, cfg)
    robot = layout.robot_arm(pairing)
    slot_of_robot = 0 if robot == "r1" else 1
    n_first = box_columns.ARM_JOINTS[layout.DOMAIN_ARMS[pairing][0]]
    robot_sl = slice(0, n_first) if slot_of_robot == 0 else slice(n_first, None)
    human_sl = slice(n_first, None) if slot_of_robot == 0 else slice(0, n_first)
    kept, attempts, lengths = [], 0, []
    while len(kept) < cfg.per_pairing:
        if attempts >= cfg.max_attempts:
            raise StageError(f"{pairing}: only {len(kept)} successful demonstrations in {attempts} attempts "
                               f"(demos.per_pairing = {cfg.per_pairing}, demos.max_attempts = {cfg.max_attempts})")
        ep = run_episode(model, env, episode_seed("demos", cfg.seed, pairing, attempts), cfg.deterministic)
        ep["attempt"] = attempts
        attempts += 1
        if ep["success"] or not cfg.success_only:
            kept.append(ep)
            lengths.append(ep["length"])
            if progress:
                progress()
    state_cols = box_columns.state_columns(pairing)
    schema = data.transitions_schema(
        state_cols, box_columns.arm_action_columns(robot), box_columns.arm_action_columns("h"),
        extra={"attempt_index": (pa.int64(), "which expert attempt (reset seed index) this demonstration came from"),
               "next.success": (pa.bool_(), "the task is solved at frame t+1 (true only on the last frame)")},
        metadata={"kind": "demos", "domain": pairing, "seed": cfg.seed, "layout": box_columns.describe(),
                  "env": env_cfg.model_dump(), "demos": cfg.model_dump(), "robot": robot,
                  "protocol": cfg.protocol,
                  "description": f"successful demonstrations of pairing {pairing} ({cfg.protocol} protocol); the "
                                 f"robot's action is action.*, the human stand-in's is human_action.* (not for "
                                 f"training)"})
    ep_idx = np.concatenate([np.full(e["length"], i) for i, e in enumerate(kept)])
    frame = np.concatenate([np.arange(e["length"]) for e in kept])
    acts = np.concatenate([e["actions"] for e in kept])
    success_flags = np.concatenate([np.arange(e["length"]) == e["length"] - 1 for e in kept])
    table = data.transitions_table(
        schema, ep_idx, frame, env.scene.dt,
        states=np.concatenate([e["states"] for e in kept]), actions=acts[:, robot_sl],
        next_states=np.concatenate([e["next_states"] for e in kept]), human_actions=acts[:, human_sl],
        extra={"attempt_index": np.concatenate([np.full(e["length"], e["attempt"]) for e in kept]),
               "next.success": success_flags})
    n_success = sum(e["success"] for e in kept)
    stats = {"demonstrations": len(kept), "successful_demonstrations": n_success, "attempts": attempts,
             "success_rate": n_success / attempts,
             "mean_demo_length": float(np.mean(lengths)), "min_demo_length": int(np.min(lengths)),
             "max_demo_length": int(np.max(lengths)), "transitions": int(table.num_rows)}
    return table, stats
