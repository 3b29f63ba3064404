"""Every task by name, imported only when asked for: ``get("block_push")``.

Each entry names where its task object lives, ``"module:attribute"``; :func:`get` imports that module and no other,
so the stages and tools of one task never load (or, for DVC, depend on) another's code. Adding a task of your own is
one module with the task object and one entry here (the README's "Tasks: adding one of your own")::

    TASKS = {..., "puck_slide": "lfdt.tasks.puck_slide:TASK"}

The registry cannot be followed by reading imports (``tests/test_dvc_deps.py`` knows: a stage that looks its task
up here lists that task's module in its dvc.yaml deps).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from lfdt.errors import StageError

if TYPE_CHECKING:  # only for the hints: importing the registry imports no task and nothing of one
    from lfdt.config import TwinParams
    from lfdt.tasks.base import Task

TASKS: dict[str, str] = {
    "box_push": "lfdt.tasks.box_push.task:TASK",
    "block_push": "lfdt.tasks.block_push:TASK",
    "peg_insertion": "lfdt.tasks.peg_insertion:TASK",
}
"""Every task by name: ``"module:attribute"`` of its task object."""
NAMES: tuple[str, ...] = tuple(TASKS)
SIMULATED_ONLY: tuple[str, ...] = ("box_push",)
"""Tasks with no real-robot counterpart (arms with joints and torque commands, not a plane)."""
PLANAR: tuple[str, ...] = tuple(n for n in TASKS if n not in SIMULATED_ONLY)
"""The real-robot tasks (:class:`lfdt.tasks.base.PlanarTask`): those the twin, the rig and the robot CLI run."""


def get(name: str) -> Task:
    """The task called ``name`` (its module imported now); ValueError naming the known ones otherwise."""
    try:
        entry = TASKS[name]
    except KeyError:
        raise ValueError(f"unknown task {name!r}; expected one of {tuple(TASKS)}") from None
    module, attribute = entry.split(":")
    return getattr(importlib.import_module(module), attribute)


def check_twin_names(twin: TwinParams) -> None:
    """Every task name ``twin`` (params.yaml's twin section) gives, in ``tasks``, ``task_translator`` or ``task_bc``,
    is a real-robot task (:data:`PLANAR`); a :class:`lfdt.errors.StageError` naming the key and the known names
    otherwise. Checked by the preflight stage before any stage runs, and by the twin stages themselves."""
    for key in ("tasks", "task_translator", "task_bc"):
        unknown = sorted(set(getattr(twin, key)) - set(PLANAR))
        if unknown:
            raise StageError(f"params.yaml twin.{key}: unknown task(s) {unknown}; the real-robot tasks are "
                             f"{list(PLANAR)}")
