"""The twin's recordings (stage ``twin_collect``): random motion and demonstrations in the MuJoCo twin through the
hardware-free rig (:mod:`lfdt.rig`), or the robots' recordings imported (backend 'real')."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from lfdt import data, layout
from lfdt.config import TWIN_ATTEMPTS_PER_DEMO, TwinParams
from lfdt.errors import StageError
from lfdt.tasks import registry
from lfdt.twin.common import SeedJob, check_real_recording, recordings, twin_schema


def record_random(task: str, domain: str, samples: int, episode_steps: int, seed: int, out_dir,
                  hold_max: int = 3, reach: float = 0.008) -> int:
    """Random motion in the twin: every slot's target a random offset of up to ``reach`` m from its end (about
    one control step of travel, so that the motion still tells which target was sent), held 1..hold_max steps;
    one file per episode. Returns the number of transitions written."""
    from lfdt.rig.recording import EpisodeRecorder, record_random_episode
    from lfdt.rig.sim import SimRig
    from lfdt.seeding import episode_seed

    with SimRig(task, domain, human="random") as rig:
        rec = EpisodeRecorder(out_dir, twin_schema(task, domain, "random", {"seed": seed, "samples": samples}),
                              rig.control_dt)
        written, ep = 0, 0
        while written < samples:
            s = episode_seed("random", seed, domain, ep)
            rig.reset(seed=s)
            rec.start()
            written += record_random_episode(rig, rec, np.random.default_rng(s), min(episode_steps, samples - written),
                                             reach, hold_max)
            ep += 1
    return written


def record_demos(task: str, pairing: str, n: int, seed: int, out_dir, max_attempts: int | None = None) -> dict:
    """Demonstrations in X in the twin (the robot programmed, the scripted person adapting); only successful ones
    are kept."""
    from lfdt.rig.recording import EpisodeRecorder, record_demo_episode
    from lfdt.rig.sim import SimRig
    from lfdt.seeding import episode_seed
    from lfdt.tasks.demonstrators import ProgrammedMotion

    # at least 200 takes (what ten demonstrations, the paper's, always had), more for more demonstrations
    max_attempts = max(200, TWIN_ATTEMPTS_PER_DEMO * n) if max_attempts is None else max_attempts
    robot = layout.robot_arm(pairing)
    with SimRig(task, pairing, human="scripted") as rig:
        slot = rig.slots.index(robot)
        rec = EpisodeRecorder(out_dir, twin_schema(task, pairing, "demos", {"seed": seed, "demos": n}),
                              rig.control_dt)
        kept, attempts, lengths = 0, 0, []
        while kept < n:
            if attempts >= max_attempts:
                raise StageError(f"{task} {pairing}: the twin's scripted demonstrations succeeded {kept} times in "
                                 f"{attempts} takes, {n} needed (twin.demos_per_pairing)")
            obs = rig.reset(seed=episode_seed("demos", seed, pairing, attempts))
            rec.start()
            program = ProgrammedMotion(task, slot, obs, rig.control_dt)
            ok, steps = record_demo_episode(rig, rec, program, robot, rig.env.cfg.max_steps)
            attempts += 1
            if ok:
                lengths.append(steps)
                rec.finish()
                kept += 1
            else:
                rec.abort()
    return {"demonstrations": kept, "attempts": attempts, "mean_length": float(np.mean(lengths)),
            "transitions": int(np.sum(lengths))}


def collect(task: str, p: TwinParams, root: str | Path) -> dict:
    """Write (sim) or import (real) the recordings of a task for every seed, one after the other; returns statistics
    per seed and recording (the stage runs :func:`twin_collect_job` per seed side by side instead)."""
    shutil.rmtree(Path(root) / task, ignore_errors=True)
    return {f"s{seed}": collect_seed(task, p, seed, root) for seed in p.seeds}


def twin_collect_job(job: SeedJob, progress=None) -> dict:
    """The recordings of one seed's run (:func:`collect_seed`) as a worker's job."""
    p = job.params
    stats = collect_seed(job.task, p, job.seed, job.data_root)
    if progress is not None:
        progress.update(1)
    return stats


def collect_seed(task: str, p: TwinParams, seed: int, root: str | Path) -> dict:
    """The recordings of one seed's run; returns statistics per recording."""
    out = recordings(task, seed, root)
    stats = {}
    for name, path in out.items():
        shutil.rmtree(path, ignore_errors=True)
        if p.backend == "real":
            shutil.copytree(check_real_recording(p, task, name), path)
        elif name.startswith("random"):
            record_random(task, name.split("_")[1], p.random_samples, p.random_episode_steps, seed, path,
                          hold_max=p.random_hold_max)
        else:
            stats[name] = record_demos(task, name.split("_")[1], p.demos_per_pairing, seed, path)
        kind, domain = name.split("_")
        data.check_transitions(path, kind, domain, registry.get(task).layout)
        df = data.read_transitions(path)
        stats.setdefault(name, {}).update({"transitions": len(df), "episodes": int(df.episode_index.nunique())})
    return stats
