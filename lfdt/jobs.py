"""One configuration (method, demos, seed) of each matrix stage of the second half, as a job.

A matrix stage (``stages/train_translator.py``, ``track_demos``, ``train_bc``, ``evaluate``) covers one method
and one demonstration count; its seeds are independent jobs that :func:`lfdt.parallel.run_jobs` runs side by
side. Each job opens its own MLflow run, writes its own files under ``<root>/<method>-d<demos>/s<seed>/`` and
returns its metrics; the stage gathers them into one report per (method, demos).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from lfdt import bc, data, evaluation, layout, methods, reexecute, stage, tracking, translation
from lfdt.dynamics import DynamicsModels, load_random_y
from lfdt.nets import load_state, read_config, save_state
from lfdt.parallel import Progress

DEMOS = Path("data/demos")
RANDOM = Path("data/random")
DYNAMICS = Path("models/dynamics/dynamics.pt")
TRANSLATORS = Path("models/translator")
BC_DATA = Path("data/bc_train")
POLICIES = Path("models/bc")
VIDEOS = Path("reports/videos")

DATA_FILE = {"raw": None, "translated": "translated.parquet", "executed": "executed.parquet"}
"""The BC training file each kind of method (:attr:`lfdt.methods.Method.data`) writes and reads."""


@dataclass(frozen=True)
class Config:
    """One configuration of a matrix stage."""

    method: str
    demos: int
    seed: int
    params: str = "params.yaml"

    @property
    def group(self) -> str:
        """The (method, demos) a matrix stage instance covers, as in file names: ``lfdt-d50``."""
        return f"{self.method}-d{self.demos}"

    @property
    def name(self) -> str:
        """This configuration in run names: ``lfdt-d50-s0``."""
        return stage.config_name(self.method, self.demos, self.seed)

    def dir(self, root: Path) -> Path:
        """Its own directory under ``root``: ``<root>/<method>-d<demos>/s<seed>``."""
        return Path(root) / self.group / f"s{self.seed}"

    def tags(self) -> dict:
        return {"method": self.method, "demos": self.demos, "seed": self.seed, "config": self.name}


def configs(method: str, demos: int, seeds: list[int], params: str) -> list[Config]:
    """The jobs of one matrix stage instance."""
    methods.get(method)
    return [Config(method, demos, s, params) for s in seeds]


def _numeric(d: dict) -> dict:
    return {k: v for k, v in d.items() if isinstance(v, int | float) and not isinstance(v, bool)}


def load_dynamics() -> DynamicsModels:
    """F and F^-1 of Y (``models/dynamics``), frozen."""
    cfg = read_config(DYNAMICS)
    n_y, n_a = len(layout.state_columns("Y")), len(layout.action_columns("Y"))
    return load_state(DynamicsModels(n_y, n_a, cfg["dynamics"]["hidden"]), DYNAMICS)


# ----------------------------------------------------------------------------- translation

def translator_job(cfg: Config, progress: Progress | None = None) -> dict:
    """Train the translator of one configuration, translate its demonstrations, measure the translation."""
    t0 = time.perf_counter()
    p = stage.params(cfg.params)
    tcfg = translation.method_config(cfg.method, p.translator)
    torch.set_num_threads(tcfg.torch_threads)
    kin = translation.Kinematics.of_box_push(p.env)
    dyn = load_dynamics()
    demo_paths = {pr: DEMOS / f"{pr}.parquet" for pr in layout.PAIRINGS}
    episodes = {pr: data.demo_subset(path, cfg.demos, cfg.seed, pr) for pr, path in demo_paths.items()}
    demos_all = {pr: translation.load_x_transitions(demo_paths[pr], pr, episodes[pr], with_actions=True)
                 for pr in layout.PAIRINGS}
    demos, held = translation.split_held_out(demos_all, tcfg.holdout_fraction, cfg.seed)
    random_x = {pr: translation.load_x_transitions(RANDOM / f"{pr}.parquet", pr) for pr in layout.PAIRINGS}
    y_random = load_random_y(RANDOM / "Y.parquet").y
    with tracking.stage_run("train_translator", {"translator": tcfg.model_dump(), **cfg.tags()}, tags=cfg.tags(),
                            run_name=f"train_translator-{cfg.name}") as run:
        tr, stats = translation.train_translator(demos, random_x, y_random, dyn, tcfg, seed=cfg.seed,
                                                 std_floor=p.dynamics.std_floor, log=run.metrics,
                                                 progress=progress, kinematics=kin, held_out=held)
        save_state(tr, cfg.dir(TRANSLATORS) / "translator.pt", {
            **cfg.tags(), "translator": tcfg.model_dump(),
            "x_columns": {pr: translation.canonical_x_columns(pr) for pr in layout.PAIRINGS},
            "y_columns": layout.state_columns("Y"), "episodes": episodes,
            "held_out_episodes": {pr: sorted(set(h.episode.tolist())) for pr, h in (held or {}).items()}})
        df = translation.translate_demos(tr, dyn, demo_paths, episodes, tcfg, p.env.timestep * p.env.frame_skip)
        table = translation.translated_table(df, {
            "kind": "translated", "domain": "Y", **cfg.tags(), "translator": tcfg.model_dump(),
            "source_episodes": episodes, "layout": layout.describe(),
            "description": "demonstrations of X translated into domain Y; action.* are the BC labels "
                           f"({'F^-1(y_hat_t, y_hat_t+1)' if tcfg.labels == 'inverse' else 'recorded robot + F^-1'})"})
        data.write_table(table, cfg.dir(BC_DATA) / DATA_FILE["translated"])
        with torch.no_grad():
            replay = translation.replay_check(df, p.env)
            diag = translation.translator_diagnostics(tr, dyn, tcfg, demos_all, random_x, y_random,
                                                      kinematics=kin, seed=cfg.seed)
        diag.update(translation.translation_diagnostics(df, demo_paths, episodes))
        curve = stats.pop("curve")
        metrics = {**cfg.tags(), **replay, **diag, **{f"final/{k}": v for k, v in stats.pop("final").items()},
                   **stats, "translated_transitions": len(df), "job_wall_s": time.perf_counter() - t0,
                   "mlflow_run_id": run.run_id}
        run.metrics(_numeric(metrics))
    return {"metrics": metrics, "curve": [{"seed": cfg.seed, **c} for c in curve]}


# ----------------------------------------------------------------------------- re-execution (lfdt_track)

def track_job(cfg: Config, progress: Progress | None = None) -> dict:
    """Re-execute the translated demonstrations of the method's translator in Y; keep the successful ones."""
    t0 = time.perf_counter()
    p = stage.params(cfg.params)
    m = methods.get(cfg.method)
    source = Config(m.translator, cfg.demos, cfg.seed, cfg.params)
    df = data.read_transitions(source.dir(BC_DATA) / DATA_FILE["translated"])
    dyn = load_dynamics() if p.track.controller == "inverse" else None
    with tracking.stage_run("track_demos", {"track": p.track.model_dump(), **cfg.tags()}, tags=cfg.tags(),
                            run_name=f"track_demos-{cfg.name}") as run:
        out, stats = reexecute.execute(df, p.env, p.track, dyn,
                                       progress=(lambda: progress.update(1)) if progress is not None else None)
        table = translation.translated_table(out, {
            "kind": "executed", "domain": "Y", **cfg.tags(), "track": p.track.model_dump(),
            "source": str(source.dir(BC_DATA) / DATA_FILE["translated"]), "layout": layout.describe(),
            "description": "translated demonstrations re-executed in Y in closed loop; only the executions that "
                           "solved the task; states and actions as really visited and sent"})
        data.write_table(table, cfg.dir(BC_DATA) / DATA_FILE["executed"])
        metrics = {**cfg.tags(), **stats, "job_wall_s": time.perf_counter() - t0, "mlflow_run_id": run.run_id}
        run.metrics(_numeric(metrics))
    return {"metrics": metrics}


# ----------------------------------------------------------------------------- behaviour cloning

def bc_tasks(cfg: Config) -> list[bc.BCTask]:
    """What the members of a method's policy learn from."""
    m = methods.get(cfg.method)
    src = cfg.dir(BC_DATA)
    if m.data == "raw":
        return bc.tasks_for(cfg.method, raw_demos={pr: data.read_transitions(src / f"raw_{pr}.parquet")
                                                   for pr in layout.PAIRINGS})
    return bc.tasks_for(cfg.method, translated=data.read_transitions(src / DATA_FILE[m.data]))


def bc_job(cfg: Config, progress: Progress | None = None) -> dict:
    """Behaviour cloning of one configuration from its training set."""
    t0 = time.perf_counter()
    p = stage.params(cfg.params)
    bcfg = p.bc
    torch.set_num_threads(bcfg.torch_threads)
    tasks = bc_tasks(cfg)
    with tracking.stage_run("train_bc", {"bc": bcfg.model_dump(), **cfg.tags()}, tags=cfg.tags(),
                            run_name=f"train_bc-{cfg.name}") as run:
        members, metrics, curves = [], {}, []
        for task in tasks:
            member, st = bc.train_member(task, bcfg, cfg.seed, log=run.metrics, progress=progress)
            members.append(member)
            for c in st.pop("curve"):
                curves.append({"seed": cfg.seed, "member": task.name,
                               **{k.split("/")[-1]: v for k, v in c.items()}})
            metrics.update({f"{task.name}/{k}": v for k, v in st.items()})
        bc.BCPolicy(members).save(cfg.dir(POLICIES), {**cfg.tags(), "bc": bcfg.model_dump(),
                                                      "members": [t.name for t in tasks]})
        metrics.update({**cfg.tags(), "job_wall_s": time.perf_counter() - t0, "mlflow_run_id": run.run_id})
        run.metrics(_numeric(metrics))
    return {"metrics": metrics, "curve": curves}


# ----------------------------------------------------------------------------- evaluation

def evaluate_job(cfg: Config, progress: Progress | None = None) -> dict:
    """Run one configuration's policy from the evaluation start states (the same for every configuration)."""
    t0 = time.perf_counter()
    p = stage.params(cfg.params)
    ecfg = p.evaluation
    torch.set_num_threads(1)
    policy, _ = bc.BCPolicy.load(cfg.dir(POLICIES))
    tags = {**cfg.tags(), "domain": "Y"}
    with tracking.stage_run("evaluate", {"evaluation": ecfg.model_dump(), **cfg.tags()}, tags=tags,
                            run_name=f"evaluate-{cfg.name}") as run:
        trials = evaluation.run_trials(policy, p.env, ecfg.trials, ecfg.videos, cfg.dir(VIDEOS), ecfg.video_size,
                                       progress=progress)
        ok = np.array([t["success"] for t in trials])
        summary = {**cfg.tags(), "successes": int(ok.sum()), "trials": len(trials),
                   "success_rate": float(ok.mean()),
                   f"success_rate_first{evaluation.PAPER_TRIALS}": float(ok[:evaluation.PAPER_TRIALS].mean()),
                   "mean_final_box_distance_m": float(np.mean([t["final_box_distance_m"] for t in trials])),
                   "mean_final_yaw_error_rad": float(np.mean([t["final_yaw_error_rad"] for t in trials])),
                   "job_wall_s": time.perf_counter() - t0, "mlflow_run_id": run.run_id}
        run.metrics(_numeric(summary))
        if ecfg.videos:
            run.artifact(cfg.dir(VIDEOS), "videos")
    rows = [{"method": cfg.method, "demos": cfg.demos, "seed": cfg.seed, "trial": t["trial"], "start_seed": t["seed"],
             "success": bool(t["success"]), "steps": t["steps"], "final_box_distance_m": t["final_box_distance_m"],
             "final_yaw_error_rad": t["final_yaw_error_rad"]} for t in trials]
    return {"metrics": summary, "trials": rows}


# ----------------------------------------------------------------------------- experts (first half)

EXPERTS = Path("models/experts")
EXPERT_CHECKPOINTS = Path("checkpoints/experts")
EXPERT_REPORTS = Path("reports/experts")


def expert_job(job: tuple[str, str], progress: Progress | None = None) -> dict:
    """Train (or resume) the SAC expert of one pairing, evaluate it on fresh seeds, save it: ``job`` is
    (pairing, params path)."""
    from lfdt import experts

    pairing, params_path = job
    t0 = time.perf_counter()
    p = stage.params(params_path)
    cfg, env_cfg, demos_cfg = p.experts, p.env, p.demos
    out = EXPERTS / pairing
    with tracking.stage_run("train_experts", {"env": env_cfg.model_dump(), "experts": cfg.model_dump(),
                                              **experts.protocol_doc(demos_cfg)},
                            tags={"pairing": pairing, "seed": cfg.seed, "protocol": demos_cfg.protocol},
                            run_name=f"train_experts-{pairing}") as run:
        model, stats = experts.train_expert(pairing, env_cfg, cfg, demos_cfg, EXPERT_CHECKPOINTS / pairing,
                                            log=run.metrics, progress=progress)
        ev = experts.evaluate_expert(model, pairing, env_cfg, demos_cfg, cfg.eval_episodes, cfg.seed)
        curve = stats.pop("curve")
        summary = {"pairing": pairing, "protocol": demos_cfg.protocol, **ev, **stats,
                   "job_wall_s": time.perf_counter() - t0, "mlflow_run_id": run.run_id}
        experts.save_expert(model, out, pairing, env_cfg, cfg, demos_cfg, {"evaluation": ev, "training": stats})
        stage.write_json(EXPERT_REPORTS / f"{pairing}_train.json", summary)
        stage.write_csv(EXPERT_REPORTS / f"{pairing}_curve.csv",
                        [{"timesteps": c["timesteps"], "success_rate": c["train/success_rate_last100"],
                          "episode_return": c["train/episode_return_last100"]} for c in curve])
        run.metrics({f"eval/{k}": v for k, v in _numeric(ev).items()})
        run.metrics(_numeric(stats))
        run.artifact(out / "config.json")
        run.artifact(EXPERT_REPORTS / f"{pairing}_curve.csv")
        experts.Checkpoints(EXPERT_CHECKPOINTS / pairing, "").clear()
    return summary
