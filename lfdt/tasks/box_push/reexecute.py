"""Closed-loop re-execution of translated demonstrations in domain Y (the ``lfdt_track`` row; our extension).

LfDT's BC learns from translated states and from action labels that F^-1 gives for consecutive translated
states; nothing guarantees that those labels, executed one after the other, reproduce the demonstration. Here
every translated demonstration is executed in the real Y environment instead, from its first translated state,
by a controller that at each step aims for the next translated state from the state actually reached:

* ``jacobian``: resolved-rate control of both end effectors towards their next translated positions (the arms
  are overdamped, so a torque of ``damping * qdot / gear`` holds a joint speed ``qdot``);
* ``inverse``: a_t = F^-1(y_t, y_hat_t+1), the learned inverse model used as the controller.

An execution that solves the task within the demonstration's length plus ``settle_steps`` becomes one BC
demonstration, with the states actually visited and the actions actually sent; the others are dropped.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pandas as pd
import torch

from lfdt import layout
from lfdt.config import EnvConfig, TrackConfig
from lfdt.dynamics import DynamicsModels
from lfdt.errors import StageError
from lfdt.tasks.box_push import columns as box_columns
from lfdt.tasks.box_push.env import BoxPushEnv, forward_kinematics, jacobian


def _jacobian_action(env: BoxPushEnv, target_ee: np.ndarray, gain: float) -> np.ndarray:
    """Torques that move each arm's end towards ``target_ee`` (2, 2) within one control step (times ``gain``)."""
    u = []
    n1, n2 = env.scene.nq_arm
    for k, (arm, sl) in enumerate(zip(env.scene.arms, (slice(0, n1), slice(n1, n1 + n2)))):
        q = env.data.qpos[sl]
        v = gain * (target_ee[k] - forward_kinematics(arm, q)) / env.scene.dt
        qdot = np.linalg.pinv(jacobian(arm, q)) @ v
        u.append(np.asarray(arm.cfg.damping) * qdot / np.asarray(arm.cfg.gears))
    return np.clip(np.concatenate(u), -1.0, 1.0)


def execute(df: pd.DataFrame, env_cfg: EnvConfig, cfg: TrackConfig, dyn: DynamicsModels | None = None,
            progress: Callable[[], None] | None = None) -> tuple[pd.DataFrame, dict]:
    """Re-execute every translated demonstration of ``df`` (Y layout) in Y; returns the successful executions as
    transitions (same columns as ``df``) and statistics."""
    if cfg.controller == "inverse" and dyn is None:
        raise ValueError("track.controller = 'inverse' needs the dynamics models")
    env = BoxPushEnv("Y", env_cfg)
    cols = box_columns.state_columns("Y")
    s_cols = [layout.STATE_PREFIX + c for c in cols]
    n2s_cols = [layout.NEXT_STATE_PREFIX + c for c in cols]
    a_cols = [layout.ACTION_PREFIX + c for c in box_columns.action_columns("Y")]
    q_idx = [cols.index(c) for c in cols if ".q" in c]
    box_idx = [cols.index(c) for c in box_columns.OBJECT_COLUMNS]
    ee_idx = [[cols.index(f"{a}.ee_x"), cols.index(f"{a}.ee_y")] for a in ("r1", "r2")]
    limits = np.concatenate([np.asarray(a.cfg.joint_range) for a in env.scene.arms])
    kept, lengths, n_exec, n_success = [], [], 0, 0
    for _, g in df.groupby("episode_index", sort=True):
        g = g.sort_values("frame_index")
        plan = np.concatenate([g[s_cols].to_numpy(float), g[n2s_cols].to_numpy(float)[-1:]])
        qpos = np.concatenate([np.clip(plan[0, q_idx], -limits, limits), plan[0, box_idx]])
        obs = env.set_state(qpos)
        states, actions, nexts = [], [], []
        success = False
        n_exec += 1
        for t in range(len(plan) - 1 + cfg.settle_steps):
            target = plan[min(t + 1, len(plan) - 1)]
            if cfg.controller == "jacobian":
                a = _jacobian_action(env, target[ee_idx], cfg.gain)
            else:
                with torch.no_grad():
                    y_n = dyn.y_norm(torch.as_tensor(obs, dtype=torch.float32)[None])
                    y2_n = dyn.y_norm(torch.as_tensor(target, dtype=torch.float32)[None])
                    a = np.clip(dyn.inverse_model(y_n, y2_n)[0].numpy().astype(float), -1.0, 1.0)
            nobs, _, term, _, _ = env.step(a)
            states.append(obs)
            actions.append(a)
            nexts.append(nobs)
            obs = nobs
            if term:
                success = True
                break
        n_success += success
        if progress is not None:
            progress()
        if not success and cfg.success_only:
            continue
        n = len(states)
        out = pd.DataFrame(np.array(states), columns=s_cols)
        out[a_cols] = np.array(actions)
        out[n2s_cols] = np.array(nexts)
        out.insert(0, "episode_index", len(kept))
        out.insert(1, "frame_index", np.arange(n))
        out.insert(2, "timestamp", np.arange(n) * env.scene.dt)
        out["source_pairing"] = g.source_pairing.iloc[0]
        out["source_episode_index"] = int(g.source_episode_index.iloc[0])
        kept.append(out)
        lengths.append(n)
    n_ok = len(kept) if cfg.success_only else n_success
    stats = {"executions": n_exec, "successful_executions": n_ok, "kept_executions": len(kept),
             "execution_success_rate": n_ok / max(n_exec, 1),
             "mean_execution_length": float(np.mean(lengths)) if lengths else 0.0}
    if not kept:
        raise StageError(f"none of {n_exec} translated demonstrations succeeded when re-executed in Y "
                           f"(track.controller = {cfg.controller!r}); lfdt_track has no data to learn from")
    return pd.concat(kept, ignore_index=True), stats
