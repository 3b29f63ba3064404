"""The behaviour-cloning job: one configuration's policy from its training set."""

from __future__ import annotations

import time

import torch

from lfdt import bc, data, layout, methods, mlflow_runs, stage
from lfdt.jobs.common import DATA_FILE, TASK, Config, numeric
from lfdt.nets import torch_device
from lfdt.parallel import Progress


def bc_tasks(cfg: Config) -> list[bc.BCTask]:
    """What the members of a method's policy learn from."""
    m = methods.get(cfg.method)
    src = cfg.dir(cfg.bc_data_dir)
    if m.data == "raw":
        return bc.tasks_for(cfg.method, raw_demos={pr: data.read_transitions(src / f"raw_{pr}.parquet", kind="demos",
                                                                             domain=pr) for pr in layout.PAIRINGS},
                            tl=TASK)
    return bc.tasks_for(cfg.method, translated=data.read_transitions(src / DATA_FILE[m.data], kind=m.data, domain="Y"),
                        tl=TASK)


def bc_job(cfg: Config, progress: Progress | None = None) -> dict:
    """Behaviour cloning of one configuration from its training set."""
    t0 = time.perf_counter()
    p = stage.params(cfg.params)
    bcfg = p.bc
    torch.set_num_threads(bcfg.torch_threads)
    device = torch_device(p.device)
    tasks = bc_tasks(cfg)
    with mlflow_runs.stage_run("train_bc", {"bc": bcfg.model_dump(), **cfg.tags(), "device": p.device},
                               tags=cfg.tags(), run_name=f"{cfg.name} train_bc") as run:
        members, metrics, curves = [], {}, []
        for task in tasks:
            member, st = bc.train_member(task, bcfg, cfg.seed, log=run.metrics, progress=progress, device=device)
            members.append(member)
            for c in st.pop("curve"):
                curves.append({"seed": cfg.seed, "member": task.name,
                               **{k.split("/")[-1]: v for k, v in c.items()}})
            metrics.update({f"{task.name}/{k}": v for k, v in st.items()})
        bc.BCPolicy(members, TASK).save(cfg.dir(cfg.policies_dir), {**cfg.tags(), "bc": bcfg.model_dump(),
                                                      "members": [t.name for t in tasks]})
        metrics.update({**cfg.tags(), "job_wall_s": time.perf_counter() - t0, "mlflow_run_id": run.run_id})
        run.metrics(numeric(metrics))
    return {"metrics": metrics, "curve": curves}
