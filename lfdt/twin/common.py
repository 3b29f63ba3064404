"""What the twin's stages share: one seed's job, the params it reads again in its worker, the recordings' folders and
their Parquet schema (the same for the twin's recordings and the robots').

The twin's stages mirror :mod:`lfdt.box_push_jobs`: :mod:`lfdt.twin.collect` (``twin_collect``), :mod:`lfdt.twin.train`
(``twin_train``) and :mod:`lfdt.twin.evaluate` (``twin_evaluate``), each importing only what its stage runs, so that
an edit of the translator reruns training, never data collection.

Data layout per task and seed (``<root>/<task>/s<seed>/``, the root dvc.yaml's ``paths.twin_data``), each a
recording directory of per-episode Parquet files: ``random_Y``, ``random_R1H``, ``random_HR2``, ``demos_R1H``,
``demos_HR2``. With backend 'sim' the twin writes them, one data set per seed; with backend 'real' they are the
recordings made on the robots with ``python -m lfdt.robot record-random`` / ``record-demos`` under
``twin.real_dir/<task>/`` (one set, the same for every seed). Models go to ``<models>/<task>/s<seed>/`` (dvc.yaml's
``paths.twin_models``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from lfdt import data, layout
from lfdt.config import TwinParams
from lfdt.errors import StageError
from lfdt.tasks import registry


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


RECORDING_NAMES: tuple[str, ...] = (*(f"random_{d}" for d in layout.DOMAINS), *(f"demos_{p}" for p in layout.PAIRINGS))
"""The recordings of a task, one folder each."""


def recordings(task: str, seed: int, root: str | Path) -> dict[str, Path]:
    """The recording directories of a task's run with one seed under ``root`` (the twin's data folder)."""
    base = Path(root) / task / f"s{seed}"
    return {n: base / n for n in RECORDING_NAMES}


def check_real_recording(p: TwinParams, task: str, name: str) -> Path:
    """The folder of recording ``name`` of ``task`` made on the robots (backend 'real'), checked where the user put
    it: a StageError naming ``twin.real_dir``'s folder and the command that records it when it holds no episode, a
    DataFileError naming the episode file that is not this recording's (:func:`lfdt.data.check_transitions`)."""
    src = Path(p.real_dir) / task / name
    if not any(src.glob("episode_*.parquet")):
        command = "record-random" if name.startswith("random") else "record-demos"
        raise StageError(f"params.yaml twin.backend is 'real', but {src} holds no recording (episode_*.parquet; "
                         f"twin.real_dir = {p.real_dir!r}); record it with `python -m lfdt.robot {command}`")
    kind, domain = name.split("_")
    data.check_transitions(src, kind, domain, registry.get(task).layout)
    return src


def check_real_recordings(p: TwinParams) -> None:
    """Every recording of every task of ``twin.tasks`` is there (backend 'real'; the preflight stage's check)."""
    for task in p.tasks:
        for name in RECORDING_NAMES:
            check_real_recording(p, task, name)


@dataclass(frozen=True)
class SeedJob:
    """One seed's share of a twin stage, run in a worker process (:func:`lfdt.parallel.run_jobs`), with the params
    the stage validated (a worker does not read params.yaml again)."""

    task: str
    seed: int
    params: TwinParams
    """params.yaml's ``twin``."""
    device: str
    """params.yaml's ``device``: the training device."""
    data_root: str | None = None
    """The twin's data folder (its ``<task>/s<seed>/`` recordings)."""
    models_dir: str | None = None
    """This seed's models (``<models>/<task>/s<seed>/``)."""
    video_dir: str | None = None
    """Where this seed's rollout videos go (None: no videos)."""
