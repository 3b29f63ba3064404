"""LfDT and BC without translation on the real-robot tasks, with the simulated experiment's code.

Data layout per task and seed (``<root>/<task>/s<seed>/``, the root dvc.yaml's ``paths.twin_data``), each a
recording directory of per-episode Parquet files: ``random_Y``, ``random_R1H``, ``random_HR2``, ``demos_R1H``,
``demos_HR2``. With backend 'sim' the twin writes them, one data set per seed; with backend 'real' they are the
recordings made on the robots with ``python -m lfdt.robot record-random`` / ``record-demos`` under
``twin.real_dir/<task>/`` (one set, the same for every seed). Models go to ``<models>/<task>/s<seed>/`` (dvc.yaml's
``paths.twin_models``).

Training reuses :mod:`lfdt.dynamics`, :mod:`lfdt.translation` and :mod:`lfdt.bc` with the task's layout:
states are end positions (the robots' by forward kinematics, the hand's by its tag) and the object's pose,
actions are target end positions, so BC labels from F^-1 are not clipped to [-1, 1].
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from lfdt import bc, data, layout, methods, translation
from lfdt.config import TwinParams
from lfdt.dynamics import fit_dynamics, load_random_y
from lfdt.nets import save_state
from lfdt.tasks import registry
from lfdt.twin import METHODS
from lfdt.twin.env import TwinConfig, TwinEnv


def twin_schema(task: str, domain: str, kind: str, metadata: dict):
    """The Parquet schema of twin and robot recordings (the same conventions as the simulated experiment's data):
    'random' records both slots' relative targets, 'demos' only the robot's."""
    tl = registry.get(task).layout
    if kind == "random":
        actions = tl.action_columns(domain)
    else:
        actions = tl.arm_action_columns(layout.robot_arm(domain))
    return data.transitions_schema(tl.state_columns(domain), actions, metadata={
        "kind": kind, "task": task, "domain": domain, "layout": tl.describe(), **metadata})


def record_random(task: str, domain: str, samples: int, episode_steps: int, seed: int, out_dir,
                  hold_max: int = 3, reach: float = 0.008) -> int:
    """Random motion in the twin: every slot's target a random offset of up to ``reach`` m from its end (about
    one control step of travel, so that the motion still tells which target was sent), held 1..hold_max steps;
    one file per episode. Returns the number of transitions written."""
    from lfdt.robot.recording import EpisodeRecorder, record_random_episode
    from lfdt.robot.sim_rig import SimRig
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


def record_demos(task: str, pairing: str, n: int, seed: int, out_dir, max_attempts: int = 200) -> dict:
    """Demonstrations in X in the twin (the robot programmed, the scripted person adapting); only successful ones
    are kept."""
    from lfdt.robot.recording import EpisodeRecorder, record_demo_episode
    from lfdt.robot.sim_rig import SimRig
    from lfdt.seeding import episode_seed
    from lfdt.twin.programs import ProgrammedMotion

    robot = layout.robot_arm(pairing)
    with SimRig(task, pairing, human="scripted") as rig:
        slot = rig.slots.index(robot)
        rec = EpisodeRecorder(out_dir, twin_schema(task, pairing, "demos", {"seed": seed, "demos": n}),
                              rig.control_dt)
        kept, attempts, lengths = 0, 0, []
        while kept < n:
            if attempts >= max_attempts:
                raise RuntimeError(f"{task} {pairing}: {kept} successful demonstrations in {attempts} attempts")
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


def evaluate_policy(task: str, policy, trials: int, cfg: TwinConfig | None = None, purpose: str = "evaluation",
                    videos: int = 0, video_dir=None) -> list[dict]:
    """Trials of a policy in the twin's domain Y from fixed start states; per-trial success and the task's
    measures."""
    from lfdt.evaluation import rollout_trials

    def make_env(record: bool) -> TwinEnv:
        return registry.get(task).make_env("Y", cfg, "rgb_array" if record else None)

    results = rollout_trials(policy, make_env, trials, videos, video_dir, purpose=purpose)
    for r in results:
        r.update({k: v for k, v in r.pop("final_info").items() if k != "is_success"})
    return results


def recordings(task: str, seed: int, root: str | Path) -> dict[str, Path]:
    """The recording directories of a task's run with one seed under ``root`` (the twin's data folder)."""
    base = Path(root) / task / f"s{seed}"
    names = [f"random_{d}" for d in layout.DOMAINS] + [f"demos_{p}" for p in layout.PAIRINGS]
    return {n: base / n for n in names}


@dataclass(frozen=True)
class SeedJob:
    """One seed's share of a twin stage, run in a worker process (:func:`lfdt.parallel.run_jobs`): the stage's
    params file is read again there, so that a job carries only paths."""

    task: str
    seed: int
    params: str
    """The stage's params.yaml."""
    data_root: str | None = None
    """The twin's data folder (its ``<task>/s<seed>/`` recordings)."""
    models_dir: str | None = None
    """This seed's models (``<models>/<task>/s<seed>/``)."""
    video_dir: str | None = None
    """Where this seed's rollout videos go (None: no videos)."""


def _twin_params(job: SeedJob) -> tuple[TwinParams, str]:
    from lfdt.stage import params

    p = params(job.params)
    return p.twin, p.device


def collect(task: str, p: TwinParams, root: str | Path) -> dict:
    """Write (sim) or import (real) the recordings of a task for every seed, one after the other; returns statistics
    per seed and recording (the stage runs :func:`collect_job` per seed side by side instead)."""
    shutil.rmtree(Path(root) / task, ignore_errors=True)
    return {f"s{seed}": collect_seed(task, p, seed, root) for seed in p.seeds}


def collect_job(job: SeedJob, progress=None) -> dict:
    """The recordings of one seed's run (:func:`collect_seed`) as a worker's job."""
    p, _ = _twin_params(job)
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
            src = Path(p.real_dir) / task / name
            if not any(src.glob("episode_*.parquet")):
                command = "record-random" if name.startswith("random") else "record-demos"
                raise FileNotFoundError(f"backend 'real': no recording {src}; record it with "
                                        f"`python -m lfdt.robot {command}`")
            shutil.copytree(src, path)
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


def train(task: str, p: TwinParams, seed: int, models_dir: str | Path, root: str | Path,
          log: Callable[[dict, int], None] | None = None, device: str | torch.device = "cpu",
          progress=None) -> dict:
    """Fit F, F^-1, the translator, BC on the translation (lfdt) and BC on the raw demonstrations, all with one
    seed on ``device``, on that seed's recordings; the models go to ``models_dir`` (the seed's own directory).
    ``progress`` counts the translator's iterations."""
    tl = registry.get(task).layout
    rec = recordings(task, seed, root)
    models_dir = Path(models_dir)
    ry = load_random_y(rec["random_Y"], tl)
    dcfg = p.dynamics.model_copy(update={"seed": seed})
    dyn, dres = fit_dynamics(ry, dcfg, device=device)
    save_state(dyn, models_dir / "dynamics.pt", {"dynamics": dcfg.model_dump(), "task": task,
                                                 "state_columns": ry.state_columns})
    demo_paths = {pr: str(rec[f"demos_{pr}"]) for pr in layout.PAIRINGS}
    episodes = {pr: sorted(data.read_transitions(path, columns=["episode_index"], kind="demos", domain=pr, task=task)
                           .episode_index.unique().tolist())
                for pr, path in demo_paths.items()}
    demos = {pr: translation.load_x_transitions(demo_paths[pr], pr, episodes[pr], tl=tl, kind="demos")
             for pr in layout.PAIRINGS}
    random_x = {pr: translation.load_x_transitions(rec[f"random_{pr}"], pr, None, tl=tl, kind="random")
                for pr in layout.PAIRINGS}
    cfg = translation.method_config("lfdt", p.translator_for(task))
    train_demos, held = translation.split_held_out(demos, cfg.holdout_fraction, seed)
    trs, all_stats = translation.train_restarts(train_demos, random_x, ry.y, dyn, cfg, seed, log=log,
                                                std_floor=p.dynamics.std_floor, tl=tl, held_out=held, device=device,
                                                progress=progress)
    for r, tr in enumerate(trs):
        save_state(tr, models_dir / ("translator.pt" if r == 0 else f"translator_r{r}.pt"),
                   {"translator": cfg.model_dump(), "task": task, "seed": seed, "restart": r,
                    "init_seed": translation.restart_seed(seed, r)})
    tstats = all_stats[0]
    dt = TwinConfig().control_dt
    translated = translation.translate_demos(translation.MeanTranslator(trs), dyn, demo_paths, episodes, cfg, dt, tl,
                                             action_bounds=None)
    diag = translation.translation_diagnostics(translated, demo_paths, episodes, tl)
    raw = {pr: data.read_transitions(path, kind="demos", domain=pr, task=task) for pr, path in demo_paths.items()}
    out = {"dynamics": {k: v for k, v in dres.items() if not isinstance(v, dict | list)},
           "translator": {"wall_time_s": sum(st["wall_time_s"] for st in all_stats), **tstats["final"], **diag,
                          **{f"hand_offset_m/{c}": v for c, v in trs[0].hand_offset_m(tl).items()}}}
    bcfg = p.bc_for(task)
    for method in METHODS:
        members_data = bc.tasks_for(method, translated=translated, raw_demos=raw, tl=tl)
        if bcfg.recovery_copies and methods.get(method).data != "raw":
            for t in members_data:
                t.frame = bc.recovery_augment(t.frame, dyn, tl, bcfg.recovery_copies, bcfg.recovery_noise, seed,
                                              action_bounds=None)
        members = []
        for t in members_data:
            m, st = bc.train_member(t, bcfg, seed, device=device)
            members.append(m)
            out[f"bc/{method}/{t.name}"] = {k: v for k, v in st.items() if k != "curve"}
        bc.BCPolicy(members, tl, action_bounds=None).save(models_dir / method, {
            "method": method, "task": task, "seed": seed, "bc": bcfg.model_dump(),
            "members": [t.name for t in members_data]})
    return out


def train_job(job: SeedJob, progress=None) -> dict:
    """:func:`train` of one seed as a worker's job, in an MLflow run of its own (``twin_train``, tagged with the task
    and seed); returns the results with the run's id."""
    from lfdt import mlflow_runs
    from lfdt.nets import torch_device
    from lfdt.stage import numeric

    p, device_name = _twin_params(job)
    torch.set_num_threads(1)  # each worker one core; the models' own torch_threads apply inside
    run_params = {"twin": {"seeds": p.seeds, "dynamics": p.dynamics.model_dump(),
                           "translator": p.translator_for(job.task).model_dump(),
                           "bc": p.bc_for(job.task).model_dump()},
                  "device": device_name}
    with mlflow_runs.stage_run("twin_train", run_params, tags={"task": job.task, "seed": job.seed},
                               run_name=f"{job.task}-s{job.seed} twin_train") as run:
        def log(m: dict, i: int) -> None:
            run.metrics({f"translator/{k}": v for k, v in m.items()}, i)

        res = train(job.task, p, job.seed, job.models_dir, job.data_root, log=log, device=torch_device(device_name),
                    progress=progress)
        run.metrics(numeric({f"{k}/{kk}": vv for k, v in res.items() for kk, vv in v.items()}))
        return {**res, "mlflow_run_id": run.run_id}


def load_policy(task: str, method: str, models_dir: str | Path) -> bc.BCPolicy:
    """A trained twin policy (target end positions of both robots from the Y state)."""
    policy, _ = bc.BCPolicy.load(Path(models_dir) / method, registry.get(task).layout, action_bounds=None)
    return policy


def evaluate_seed(task: str, p: TwinParams, seed: int, models_dir: str | Path,
                  video_root: str | Path | None = None) -> list[dict]:
    """Per-trial results of both methods with one seed's policies (``models_dir``) in the twin's Y, from the fixed
    start states of ``p.start_states`` (the same for every seed); ``p.videos`` videos of each method under
    ``video_root/<task>-<method>`` when it is given."""
    rows = []
    with torch.no_grad():
        for method in METHODS:
            policy = load_policy(task, method, models_dir)
            vdir = Path(video_root) / f"{task}-{method}" if video_root else None
            for r in evaluate_policy(task, policy, p.trials, purpose=p.start_states,
                                     videos=p.videos if vdir else 0, video_dir=vdir):
                rows.append({"task": task, "method": method, "seed": seed, "trial": r["trial"],
                             "success": bool(r["success"]), "steps": r["steps"], "start_seed": r["seed"]})
    return rows


def evaluate_job(job: SeedJob, progress=None) -> list[dict]:
    """:func:`evaluate_seed` as a worker's job."""
    p, _ = _twin_params(job)
    torch.set_num_threads(1)
    rows = evaluate_seed(job.task, p, job.seed, job.models_dir, job.video_dir)
    if progress is not None:
        progress.update(1)
    return rows
