"""LfDT and BC without translation trained on one seed's twin recordings (stage ``twin_train``), with the simulated
experiment's code: :mod:`lfdt.dynamics`, :mod:`lfdt.translation` and :mod:`lfdt.bc` with the task's layout. States
are end positions (the robots' by forward kinematics, the hand's by its tag) and the object's pose, actions are target
end positions, so BC labels from F^-1 are not clipped to [-1, 1]."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import torch

from lfdt import bc, data, layout, methods
from lfdt.config import TwinParams
from lfdt.dynamics import fit_dynamics, load_random_y
from lfdt.nets import save_state
from lfdt.tasks import registry
from lfdt.tasks.planar_env import TwinConfig
from lfdt.translation.apply import translate_demos, translation_diagnostics
from lfdt.translation.model import MeanTranslator
from lfdt.translation.restarts import restart_seed, train_restarts
from lfdt.translation.transitions import load_x_transitions, split_held_out
from lfdt.twin import TWIN_METHODS
from lfdt.twin.common import SeedJob, recordings


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
    demos = {pr: load_x_transitions(demo_paths[pr], pr, episodes[pr], tl=tl, kind="demos")
             for pr in layout.PAIRINGS}
    random_x = {pr: load_x_transitions(rec[f"random_{pr}"], pr, None, tl=tl, kind="random")
                for pr in layout.PAIRINGS}
    cfg = methods.translator_config("lfdt", p.translator_for(task))
    train_demos, held = split_held_out(demos, cfg.holdout_fraction, seed)
    trs, all_stats = train_restarts(train_demos, random_x, ry.y, dyn, cfg, seed, log=log,
                                    std_floor=p.dynamics.std_floor, tl=tl, held_out=held, device=device,
                                    progress=progress)
    for r, tr in enumerate(trs):
        save_state(tr, models_dir / ("translator.pt" if r == 0 else f"translator_r{r}.pt"),
                   {"translator": cfg.model_dump(), "task": task, "seed": seed, "restart": r,
                    "init_seed": restart_seed(seed, r)})
    tstats = all_stats[0]
    dt = TwinConfig().control_dt
    translated = translate_demos(MeanTranslator(trs), dyn, demo_paths, episodes, cfg, dt, tl, action_bounds=None)
    diag = translation_diagnostics(translated, demo_paths, episodes, tl)
    raw = {pr: data.read_transitions(path, kind="demos", domain=pr, task=task) for pr, path in demo_paths.items()}
    out = {"dynamics": {k: v for k, v in dres.items() if not isinstance(v, dict | list)},
           "translator": {"wall_time_s": sum(st["wall_time_s"] for st in all_stats), **tstats["final"], **diag,
                          **{f"hand_offset_m/{c}": v for c, v in trs[0].hand_offset_m(tl).items()}}}
    bcfg = p.bc_for(task)
    for method in TWIN_METHODS:
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


def twin_train_job(job: SeedJob, progress=None) -> dict:
    """:func:`train` of one seed as a worker's job, in an MLflow run of its own (``twin_train``, tagged with the task
    and seed); returns the results with the run's id."""
    from lfdt import mlflow_runs
    from lfdt.nets import torch_device
    from lfdt.stage import numeric

    p, device_name = job.params, job.device
    device = torch_device(device_name)  # before the run opens: a machine without it is params.yaml's error
    torch.set_num_threads(1)  # each worker one core; the models' own torch_threads apply inside
    run_params = {"twin": {"seeds": p.seeds, "dynamics": p.dynamics.model_dump(),
                           "translator": p.translator_for(job.task).model_dump(),
                           "bc": p.bc_for(job.task).model_dump()},
                  "device": device_name}
    with mlflow_runs.stage_run("twin_train", run_params, tags={"task": job.task, "seed": job.seed},
                               run_name=f"{job.task}-s{job.seed} twin_train") as run:
        def log(m: dict, i: int) -> None:
            run.metrics({f"translator/{k}": v for k, v in m.items()}, i)

        res = train(job.task, p, job.seed, job.models_dir, job.data_root, log=log, device=device,
                    progress=progress)
        run.metrics(numeric({f"{k}/{kk}": vv for k, v in res.items() for kk, vv in v.items()}))
        return {**res, "mlflow_run_id": run.run_id}
