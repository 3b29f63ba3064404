"""LfDT and BC without translation on the real-robot tasks, with the simulated experiment's code.

Data layout per task and seed (``data/twin/<task>/s<seed>/``), each a recording directory of per-episode
Parquet files: ``random_Y``, ``random_R1H``, ``random_HR2``, ``demos_R1H``, ``demos_HR2``. With backend 'sim'
the twin writes them, one data set per seed; with backend 'real' they are the recordings made on the robots with
``python -m lfdt.robot record-random`` / ``record-demos`` under ``twin.real_dir/<task>/`` (one set, the same for
every seed). Models go to ``models/twin/<task>/s<seed>/``.

Training reuses :mod:`lfdt.dynamics`, :mod:`lfdt.translation` and :mod:`lfdt.bc` with the task's layout:
states are end positions (the robots' by forward kinematics, the hand's by its tag) and the object's pose,
actions are target end positions, so BC labels from F^-1 are not clipped to [-1, 1].
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import torch

from lfdt import bc, data, layout, translation
from lfdt.config import TwinParams
from lfdt.dynamics import fit_dynamics, load_random_y
from lfdt.nets import save_state
from lfdt.robot import twin

METHODS = ("bc_no_translation", "lfdt")
PAPER_REAL = {"block_push": {"lfdt": (10, 10), "bc_no_translation": (10, 10)},
              "peg_insertion": {"lfdt": (8, 10), "bc_no_translation": (2, 10)}}
"""The paper's real-robot results (successes, trials)."""


def recordings(task: str, seed: int, root: str | Path = "data/twin") -> dict[str, Path]:
    """The recording directories of a task's run with one seed."""
    base = Path(root) / task / f"s{seed}"
    names = [f"random_{d}" for d in layout.DOMAINS] + [f"demos_{p}" for p in layout.PAIRINGS]
    return {n: base / n for n in names}


def collect(task: str, p: TwinParams, root: str | Path = "data/twin") -> dict:
    """Write (sim) or import (real) the recordings of a task for every seed; returns statistics per seed and
    recording."""
    shutil.rmtree(Path(root) / task, ignore_errors=True)
    return {f"s{seed}": collect_seed(task, p, seed, root) for seed in p.seeds}


def collect_seed(task: str, p: TwinParams, seed: int, root: str | Path = "data/twin") -> dict:
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
            twin.record_random(task, name.split("_")[1], p.random_samples, p.random_episode_steps, seed, path,
                               hold_max=p.random_hold_max)
        else:
            stats[name] = twin.record_demos(task, name.split("_")[1], p.demos_per_pairing, seed, path)
        kind, domain = name.split("_")
        data.check_transitions(path, kind, domain, twin.LAYOUTS[task])
        df = data.read_transitions(path)
        stats.setdefault(name, {}).update({"transitions": len(df), "episodes": int(df.episode_index.nunique())})
    return stats


def train(task: str, p: TwinParams, seed: int, models_dir: str | Path, root: str | Path = "data/twin",
          log: Callable[[dict, int], None] | None = None) -> dict:
    """Fit F, F^-1, the translator, BC on the translation (lfdt) and BC on the raw demonstrations, all with one
    seed, on that seed's recordings; the models go to ``models_dir`` (the seed's own directory)."""
    tl = twin.LAYOUTS[task]
    rec = recordings(task, seed, root)
    models_dir = Path(models_dir)
    ry = load_random_y(rec["random_Y"], tl)
    dcfg = p.dynamics.model_copy(update={"seed": seed})
    dyn, dres = fit_dynamics(ry, dcfg)
    save_state(dyn, models_dir / "dynamics.pt", {"dynamics": dcfg.model_dump(), "task": task,
                                                 "state_columns": ry.state_columns})
    demo_paths = {pr: str(rec[f"demos_{pr}"]) for pr in layout.PAIRINGS}
    episodes = {pr: sorted(data.read_transitions(path, columns=["episode_index"]).episode_index.unique().tolist())
                for pr, path in demo_paths.items()}
    demos = {pr: translation.load_x_transitions(demo_paths[pr], pr, episodes[pr], tl) for pr in layout.PAIRINGS}
    random_x = {pr: translation.load_x_transitions(rec[f"random_{pr}"], pr, None, tl) for pr in layout.PAIRINGS}
    cfg = translation.method_config("lfdt", p.translator)
    train_demos, held = translation.split_held_out(demos, cfg.holdout_fraction, seed)
    tr, tstats = translation.train_translator(train_demos, random_x, ry.y, dyn, cfg, seed=seed,
                                              std_floor=p.dynamics.std_floor, log=log, tl=tl, held_out=held)
    save_state(tr, models_dir / "translator.pt", {"translator": cfg.model_dump(), "task": task, "seed": seed})
    dt = twin.TwinConfig().control_dt
    translated = translation.translate_demos(tr, dyn, demo_paths, episodes, cfg, dt, tl, action_bounds=None)
    diag = translation.translation_diagnostics(translated, demo_paths, episodes, tl)
    raw = {pr: data.read_transitions(path) for pr, path in demo_paths.items()}
    out = {"dynamics": {k: v for k, v in dres.items() if not isinstance(v, dict | list)},
           "translator": {"wall_time_s": tstats["wall_time_s"], **tstats["final"], **diag}}
    for method in METHODS:
        tasks = bc.tasks_for(method, translated=translated, raw_demos=raw, tl=tl)
        members = []
        for t in tasks:
            m, st = bc.train_member(t, p.bc, seed)
            members.append(m)
            out[f"bc/{method}/{t.name}"] = {k: v for k, v in st.items() if k != "curve"}
        bc.BCPolicy(members, tl, action_bounds=None).save(models_dir / method, {
            "method": method, "task": task, "seed": seed, "bc": p.bc.model_dump(), "members": [t.name for t in tasks]})
    return out


def load_policy(task: str, method: str, models_dir: str | Path) -> bc.BCPolicy:
    """A trained twin policy (target end positions of both robots from the Y state)."""
    policy, _ = bc.BCPolicy.load(Path(models_dir) / method, twin.LAYOUTS[task], action_bounds=None)
    return policy


def evaluate(task: str, p: TwinParams, models_dir: str | Path, video_root: str | Path | None = None) -> list[dict]:
    """Per-trial results of both methods and every seed's policies (``models_dir/s<seed>``) in the twin's Y, all
    from the same fixed evaluation start states; videos of the first seed's policies."""
    rows = []
    with torch.no_grad():
        for seed in p.seeds:
            for method in METHODS:
                policy = load_policy(task, method, Path(models_dir) / f"s{seed}")
                vdir = Path(video_root) / f"{task}-{method}" if video_root and seed == p.seeds[0] else None
                for r in twin.evaluate(task, policy, p.trials, videos=p.videos if vdir else 0, video_dir=vdir):
                    rows.append({"task": task, "method": method, "seed": seed, "trial": r["trial"],
                                 "success": bool(r["success"]), "steps": r["steps"], "start_seed": r["seed"]})
    return rows
