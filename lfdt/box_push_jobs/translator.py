"""The translator job: train G and D of a group of seeds of one configuration as one stacked model, translate each
seed's demonstrations, measure them."""

from __future__ import annotations

import contextlib
import shutil
import time
from pathlib import Path

import pandas as pd
import torch

from lfdt import data, layout, methods, mlflow_runs
from lfdt.box_push_jobs.common import DATA_FILE, DYNAMICS_FILE, LAYOUT, Config, numeric
from lfdt.config import EnvConfig
from lfdt.dynamics import load_models, load_random_y
from lfdt.nets import save_state, torch_device
from lfdt.parallel import Progress
from lfdt.tasks.box_push import columns as box_columns
from lfdt.tasks.box_push.env import arm_specs, replay_check
from lfdt.translation.apply import translate_demos, translated_table, translation_diagnostics, translator_diagnostics
from lfdt.translation.kinematics import ArmKinematics, Kinematics
from lfdt.translation.model import MeanTranslator
from lfdt.translation.restarts import restart_key, restart_log, restart_seed
from lfdt.translation.training import Member, train_translators
from lfdt.translation.transitions import Transitions, canonical_x_columns, load_x_transitions, split_held_out


def translator_job(cfgs: list[Config], progress: Progress | None = None) -> list[dict]:
    """Train the translators of a group of seeds of one configuration (each with its restarts) as one stack, then
    translate each seed's demonstrations and measure the translation. One result per seed, in order."""
    t0 = time.perf_counter()
    first = cfgs[0]
    p = first.params
    tcfg = methods.translator_config(first.method, p.translator)
    torch.set_num_threads(tcfg.torch_threads)
    device = torch_device(p.device)
    kin = box_push_kinematics(p.env)
    dyn = load_models(first.dynamics_dir / DYNAMICS_FILE)
    demo_paths = {pr: first.demos_dir / f"{pr}.parquet" for pr in layout.PAIRINGS}
    random_x = {pr: load_x_transitions(first.random_dir / f"{pr}.parquet", pr, tl=LAYOUT, kind="random")
                for pr in layout.PAIRINGS}
    y_random = load_random_y(first.random_dir / "Y.parquet", LAYOUT).y
    per_seed = []
    for cfg in cfgs:
        episodes, demos_all = seed_demos(demo_paths, cfg.demos, cfg.seed)
        demos, held = split_held_out(demos_all, tcfg.holdout_fraction, cfg.seed)
        per_seed.append((episodes, demos_all, demos, held))
    with contextlib.ExitStack() as runs_stack:
        runs = [runs_stack.enter_context(mlflow_runs.stage_run(
            "train_translator", {"translator": tcfg.model_dump(), **cfg.tags(), "device": p.device,
                                 "stack": [c.seed for c in cfgs]},
            tags=cfg.tags(), run_name=f"{cfg.name} train_translator")) for cfg in cfgs]
        members, logs = [], []
        for cfg, run, (_, _, demos, held) in zip(cfgs, runs, per_seed):
            for r in range(tcfg.restarts):
                members.append(Member(demos, restart_seed(cfg.seed, r), held))
                logs.append(restart_log(run.metrics, r))
        ckpt_dir = None if first.checkpoints_dir is None else (
            Path(first.checkpoints_dir) / first.group / ("s" + "-".join(str(c.seed) for c in cfgs)))
        trained, trained_stats = train_translators(
            members, random_x, y_random, dyn, tcfg, p.dynamics.std_floor, logs, progress, tl=LAYOUT, kinematics=kin,
            device=device, checkpoint_dir=ckpt_dir)
        results = []
        for i, (cfg, run, (episodes, demos_all, _, held)) in enumerate(zip(cfgs, runs, per_seed)):
            trs = trained[i * tcfg.restarts:(i + 1) * tcfg.restarts]
            all_stats = trained_stats[i * tcfg.restarts:(i + 1) * tcfg.restarts]
            results.append(_finish(cfg, run, trs, all_stats, episodes, demos_all, held, random_x, y_random, dyn,
                                   tcfg, demo_paths, kin, p.env, t0))
    if ckpt_dir is not None:
        shutil.rmtree(ckpt_dir, ignore_errors=True)  # every translator of the group is saved
    return results


def _finish(cfg: Config, run, trs, all_stats, episodes, demos_all, held, random_x, y_random, dyn, tcfg, demo_paths,
            kin, env_cfg: EnvConfig, t0: float) -> dict:
    """Save one seed's translators, translate its demonstrations, measure and log them."""
    for r, tr in enumerate(trs):
        save_state(tr, cfg.dir(cfg.translators_dir) / ("translator.pt" if r == 0 else f"translator_r{r}.pt"), {
            **cfg.tags(), "translator": tcfg.model_dump(), "restart": r,
            "init_seed": restart_seed(cfg.seed, r),
            "x_columns": {pr: canonical_x_columns(pr, LAYOUT) for pr in layout.PAIRINGS},
            "y_columns": LAYOUT.state_columns("Y"), "episodes": episodes,
            "held_out_episodes": {pr: sorted(set(h.episode.tolist())) for pr, h in (held or {}).items()}})
    df, diag = measure_translation(trs, dyn, tcfg, demo_paths, episodes, demos_all, random_x, y_random, kin, env_cfg,
                                   cfg.seed)
    table = translated_table(df, {
        "kind": "translated", "domain": "Y", **cfg.tags(), "translator": tcfg.model_dump(),
        "source_episodes": episodes, "layout": box_columns.describe(),
        "description": "demonstrations of X translated into domain Y; action.* are the BC labels "
                       f"({'F^-1(y_hat_t, y_hat_t+1)' if tcfg.labels == 'inverse' else 'recorded robot + F^-1'})"},
        LAYOUT)
    data.write_table(table, cfg.dir(cfg.bc_data_dir) / DATA_FILE["translated"])
    stats = dict(all_stats[0])
    curve = stats.pop("curve")
    restarts = {}  # the other restarts' selection and final losses (their curves are in MLflow)
    for r, st in enumerate(all_stats[1:], 1):
        st = dict(st)
        st.pop("curve")
        restarts.update({restart_key(r, f"final/{k}"): v for k, v in st.pop("final").items()})
        restarts.update({restart_key(r, k): v for k, v in st.items()})
    metrics = {**cfg.tags(), **diag, **{f"final/{k}": v for k, v in stats.pop("final").items()},
               **stats, **restarts, "translated_transitions": len(df), "job_wall_s": time.perf_counter() - t0,
               "mlflow_run_id": run.run_id}
    run.metrics(numeric(metrics))
    return {"metrics": metrics, "curve": [{"seed": cfg.seed, **c} for c in curve]}


def seed_demos(demo_paths: dict[str, Path], demos: int, seed: int) -> tuple[dict[str, list[int]],
                                                                          dict[str, Transitions]]:
    """A training seed's demonstrations of each pairing: their episode indices and their transitions (with the real
    robot's recorded actions, for the diagnostics)."""
    episodes = {pr: data.demo_subset(path, demos, seed, pr) for pr, path in demo_paths.items()}
    return episodes, {pr: load_x_transitions(demo_paths[pr], pr, episodes[pr], tl=LAYOUT, with_actions=True,
                                             kind="demos") for pr in layout.PAIRINGS}


def measure_translation(trs: list, dyn, tcfg, demo_paths: dict[str, Path], episodes: dict[str, list[int]],
                        demos_all: dict[str, Transitions], random_x: dict[str, Transitions], y_random, kin: Kinematics,
                        env_cfg: EnvConfig, seed: int, max_random: int = 20_000) -> tuple[pd.DataFrame, dict]:
    """Translate one seed's demonstrations with the mean of its translators (restarts) and measure them, as the
    translator stage reports them: the open-loop replay of the labels in MuJoCo, each restart's G and D on their own
    (restart 0 under the plain names) and the translation against its source. Returns the translated transitions and
    the measurements."""
    df = translate_demos(MeanTranslator(trs), dyn, demo_paths, episodes, tcfg, env_cfg.timestep * env_cfg.frame_skip,
                         LAYOUT)
    with torch.no_grad():
        out = replay_check(df, env_cfg)
        for r, tr in enumerate(trs):
            d = translator_diagnostics(tr, dyn, tcfg, demos_all, random_x, y_random, tl=LAYOUT, kinematics=kin,
                                       max_random=max_random, seed=seed)
            out.update({restart_key(r, k): v for k, v in d.items()})
    out.update(translation_diagnostics(df, demo_paths, episodes, LAYOUT))
    return df, out


def box_push_kinematics(env_cfg: EnvConfig) -> Kinematics:
    """What the translator may take from the box push's domain Y: its two 3-link robots (``translator.kinematics``)."""
    cols = LAYOUT.state_columns("Y")
    out = []
    for arm in arm_specs("Y", env_cfg):
        n = arm.name
        out.append(ArmKinematics([cols.index(f"{n}.q{i}") for i in range(arm.n)],
                                 [cols.index(f"{n}.dq{i}") for i in range(arm.n)],
                                 [cols.index(f"{n}.ee_x"), cols.index(f"{n}.ee_y")],
                                 list(arm.cfg.links), list(arm.base)))
    return Kinematics(out, env_cfg.timestep * env_cfg.frame_skip)
