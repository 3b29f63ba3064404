"""Evaluation of policies in domain Y from fixed start states, and the aggregation into Table I.

Start states come from the ``evaluation`` seed block (:mod:`lfdt.seeding`): trial i of every
method, demo count and seed starts from the same state, and no training or data-collection run
ever resets with one of these seeds. They are fixed in advance, never chosen by outcome.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

from lfdt.seeding import episode_seed

PAPER_TRIALS = 20
"""The paper's trials per seed; Table I also reports our success on the first 20 start states."""


def evaluation_seeds(trials: int, purpose: str = "evaluation") -> list[int]:
    """Reset seeds of the evaluation trials (the same for every config); 'development' gives a disjoint set."""
    return [episode_seed(purpose, 0, "Y", i) for i in range(trials)]


def rollout_trials(policy: Callable[[np.ndarray], np.ndarray], make_env: Callable[[bool], object], trials: int,
                   videos: int = 0, video_dir: Path | None = None, progress=None,
                   purpose: str = "evaluation") -> list[dict]:
    """Run a policy in environments from ``make_env(record)`` from the fixed start states of ``purpose``.

    Returns per trial: index, seed, success, steps and the last step's info (``final_info``).
    """
    results = []
    for i, seed in enumerate(evaluation_seeds(trials, purpose)):
        record = i < videos and video_dir is not None
        env = make_env(record)
        obs, info = env.reset(seed=seed)
        frames = [env.render()] if record else []
        success, steps, done = False, 0, False
        while not done:
            obs, _, term, trunc, info = env.step(policy(obs))
            steps += 1
            if record:
                frames.append(env.render())
            success, done = bool(term), term or trunc
        results.append({"trial": i, "seed": seed, "success": success, "steps": steps, "final_info": info})
        if record:
            write_video(frames, Path(video_dir) / f"trial{i:02d}.mp4", fps=env.metadata["render_fps"])
        env.close()
        if progress is not None:
            progress.update(1)
    return results


def rollout_lockstep(act: Callable[[np.ndarray], np.ndarray], make_env: Callable[[bool], object], policies: int,
                     trials: int, videos: int = 0, video_dirs: list[Path] | None = None, progress=None,
                     purpose: str = "evaluation") -> list[list[dict]]:
    """Run ``policies`` policies from the fixed start states of ``purpose``, all trials of all policies in lockstep:
    one call ``act(obs)`` per control step maps observations ``(policies, trials, obs)`` to actions ``(policies,
    trials, act)``. Every call sees every trial, finished ones included (their actions are dropped), so a policy's
    actions do not depend on which trials are still running, nor on the other policies. The first ``videos`` trials
    of policy p are filmed into ``video_dirs[p]``.

    Returns per policy, per trial: index, seed, success, steps and the last step's info (``final_info``).
    """
    seeds = evaluation_seeds(trials, purpose)
    record = [[i < videos and video_dirs is not None for i in range(trials)] for _ in range(policies)]
    envs = [[make_env(record[p][i]) for i in range(trials)] for p in range(policies)]
    obs, frames = [], [[[] for _ in range(trials)] for _ in range(policies)]
    for p in range(policies):
        row = []
        for i, env in enumerate(envs[p]):
            o, _ = env.reset(seed=seeds[i])
            row.append(o)
            if record[p][i]:
                frames[p][i].append(env.render())
        obs.append(row)
    obs = np.asarray(obs, dtype=float)
    done = np.zeros((policies, trials), dtype=bool)
    results = [[{"trial": i, "seed": seeds[i], "success": False, "steps": 0, "final_info": {}}
                for i in range(trials)] for _ in range(policies)]
    while not done.all():
        actions = act(obs)
        for p in range(policies):
            for i in np.flatnonzero(~done[p]):
                env = envs[p][i]
                o, _, term, trunc, info = env.step(actions[p, i])
                obs[p, i] = o
                r = results[p][i]
                r["steps"] += 1
                r["success"], r["final_info"] = bool(term), info
                if record[p][i]:
                    frames[p][i].append(env.render())
                if term or trunc:
                    done[p, i] = True
                    if progress is not None:
                        progress.update(1)
    for p in range(policies):
        for i in range(trials):
            if record[p][i]:
                write_video(frames[p][i], Path(video_dirs[p]) / f"trial{i:02d}.mp4",
                            fps=envs[p][i].metadata["render_fps"])
            envs[p][i].close()
    return results


def write_video(frames: list[np.ndarray], path: Path, fps: int) -> Path:
    """Encode frames as H.264 mp4 (the ffmpeg binary comes with imageio-ffmpeg; no download)."""
    import imageio.v2 as imageio

    path.parent.mkdir(parents=True, exist_ok=True)
    imageio.mimwrite(path, frames, fps=fps, codec="libx264", quality=7, macro_block_size=8)
    return path


def wilson_interval(successes: int, trials: int, z: float = 1.96) -> tuple[float, float]:
    """95 % Wilson score interval of a binomial proportion."""
    if trials == 0:
        return (0.0, 1.0)
    p = successes / trials
    denom = 1 + z * z / trials
    centre = (p + z * z / (2 * trials)) / denom
    half = z * math.sqrt(p * (1 - p) / trials + z * z / (4 * trials * trials)) / denom
    return (max(0.0, centre - half), min(1.0, centre + half))


def seed_state_interval(outcomes: np.ndarray, level: float = 0.95) -> tuple[float, float]:
    """Interval of the mean success rate that accounts for both the training seeds and the start states.

    ``outcomes`` is a (seeds, start states) array of 0/1 trial outcomes, every seed run from the same start
    states (a crossed design). Seeds and start states are both treated as random draws (:func:`crossed_interval`).
    With one seed only the start-state and residual terms remain (a within-seed interval).
    """
    lo, hi = crossed_interval(outcomes, level)
    return (max(0.0, lo), min(1.0, hi))


def paired_difference_interval(a: np.ndarray, b: np.ndarray, level: float = 0.95) -> tuple[float, float]:
    """Interval of the mean difference of two methods' success, ``a - b``, run with the same seeds from the same
    start states (both (seeds, start states) arrays of 0/1 outcomes): the pairing removes what the seeds' demonstration
    subsets and the start states' difficulty share (:func:`crossed_interval` of the differences)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if a.shape != b.shape:
        raise ValueError(f"paired outcomes need the same seeds and start states, got {a.shape} and {b.shape}")
    lo, hi = crossed_interval(a - b, level)
    return (max(-1.0, lo), min(1.0, hi))


def crossed_interval(values: np.ndarray, level: float = 0.95) -> tuple[float, float]:
    """Interval of the grand mean of a (seeds, start states) array whose rows and columns are both random draws.

    The variance of the grand mean is estimated from the two-way ANOVA mean squares as (MS_seed + MS_state -
    MS_residual) / (S T) (= var_seed / S + var_state / T + var_residual / (S T)), with Satterthwaite's degrees of
    freedom and a t quantile.
    """
    from scipy import stats

    y = np.asarray(values, dtype=float)
    if y.ndim != 2 or y.size == 0:
        raise ValueError(f"outcomes must be a non-empty (seeds, start states) array, got shape {y.shape}")
    n_s, n_t = y.shape
    m = float(y.mean())
    if n_t < 2:
        return (m, m)
    row, col = y.mean(axis=1), y.mean(axis=0)
    ms_state = n_s * float(((col - m) ** 2).sum()) / (n_t - 1)
    if n_s < 2:
        var, df = ms_state / n_t, n_t - 1
    else:
        ms_seed = n_t * float(((row - m) ** 2).sum()) / (n_s - 1)
        resid = y - row[:, None] - col[None, :] + m
        ms_res = float((resid ** 2).sum()) / ((n_s - 1) * (n_t - 1))
        terms = [(ms_seed, n_s - 1), (ms_state, n_t - 1), (-ms_res, (n_s - 1) * (n_t - 1))]
        num = sum(t for t, _ in terms)
        # a negative estimate (possible by chance) falls back to the larger of the two one-way estimates
        num = max(num, ms_seed, ms_state)
        var = num / (n_s * n_t)
        denom = sum(t * t / d for t, d in terms)
        df = num * num / denom if denom > 0 else n_s - 1
    if var <= 0:
        return (m, m)
    half = float(stats.t.ppf(0.5 + level / 2, max(df, 1.0))) * math.sqrt(var)
    return (m - half, m + half)
