"""The behaviour-cloning job: the policies of a group of seeds of one configuration, trained as stacks."""

from __future__ import annotations

import contextlib
import time

import torch

from lfdt import bc, data, layout, methods, mlflow_runs
from lfdt.box_push_jobs.common import DATA_FILE, DYNAMICS_FILE, LAYOUT, Config, numeric
from lfdt.nets import torch_device
from lfdt.parallel import Progress


def bc_tasks(cfg: Config) -> list[bc.BCTask]:
    """What the members of a method's policy learn from."""
    m = methods.get(cfg.method)
    src = cfg.dir(cfg.bc_data_dir)
    if m.data == "raw":
        return bc.tasks_for(cfg.method, raw_demos={pr: data.read_transitions(src / f"raw_{pr}.parquet", kind="demos",
                                                                             domain=pr) for pr in layout.PAIRINGS},
                            tl=LAYOUT)
    return bc.tasks_for(cfg.method, translated=data.read_transitions(src / DATA_FILE[m.data], kind=m.data, domain="Y"),
                        tl=LAYOUT)


def bc_job(cfgs: list[Config], progress: Progress | None = None) -> list[dict]:
    """Behaviour cloning of a group of seeds of one configuration from their training sets: each member of the
    method's policy (one, or one per robot) trains as a stack over the seeds. One result per seed, in order."""
    t0 = time.perf_counter()
    p = cfgs[0].params
    bcfg = p.bc
    torch.set_num_threads(bcfg.torch_threads)
    device = torch_device(p.device)
    tasks = [bc_tasks(cfg) for cfg in cfgs]
    if bcfg.recovery_copies and methods.get(cfgs[0].method).data != "raw":
        from lfdt.dynamics import load_models

        dyn = load_models(cfgs[0].dynamics_dir / DYNAMICS_FILE)
        for cfg, ts in zip(cfgs, tasks):
            for t in ts:
                t.frame = bc.recovery_augment(t.frame, dyn, LAYOUT, bcfg.recovery_copies, bcfg.recovery_noise,
                                              cfg.seed)
    names = [t.name for t in tasks[0]]
    seeds = [cfg.seed for cfg in cfgs]
    with contextlib.ExitStack() as runs_stack:
        runs = [runs_stack.enter_context(mlflow_runs.stage_run(
            "train_bc", {"bc": bcfg.model_dump(), **cfg.tags(), "device": p.device, "stack": seeds},
            tags=cfg.tags(), run_name=f"{cfg.name} train_bc")) for cfg in cfgs]
        members = [[] for _ in cfgs]
        metrics = [{} for _ in cfgs]
        curves = [[] for _ in cfgs]
        for j, name in enumerate(names):
            trained, stats = bc.train_members([t[j] for t in tasks], bcfg, seeds, [r.metrics for r in runs], progress,
                                              device)
            for k, (member, st) in enumerate(zip(trained, stats)):
                members[k].append(member)
                st = dict(st)
                for c in st.pop("curve"):
                    curves[k].append({"seed": seeds[k], "member": name,
                                      **{key.split("/")[-1]: v for key, v in c.items()}})
                metrics[k].update({f"{name}/{key}": v for key, v in st.items()})
        results = []
        for k, (cfg, run) in enumerate(zip(cfgs, runs)):
            bc.BCPolicy(members[k], LAYOUT).save(cfg.dir(cfg.policies_dir), {**cfg.tags(), "bc": bcfg.model_dump(),
                                                                            "members": names})
            metrics[k].update({**cfg.tags(), "job_wall_s": time.perf_counter() - t0, "mlflow_run_id": run.run_id})
            run.metrics(numeric(metrics[k]))
            results.append({"metrics": metrics[k], "curve": curves[k]})
    return results
