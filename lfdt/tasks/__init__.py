"""The real-robot tasks, one module each, behind one interface (:class:`lfdt.tasks.base.PlanarTask`).

The twin, the recording tools, the rig and the DVC stages look a task up here by name and never branch on it.

Adding a task of your own: write ``lfdt/tasks/my_task.py`` with a subclass of ``PlanarTask`` (its plane, object
angle and workspace; its scene parts, start states, success rule, programmed robot motion and scripted person;
an example rig), add one entry below, and list it in ``dvc.yaml``'s twin matrix. For example::

    class Slide(PlanarTask):
        name, plane, angle, angle_axis = "slide", ("x", "y"), "yaw", "z"
        workspace = np.array([[-0.2, 0.0], [0.2, 0.3]])
        def object_xml(self, arms): ...
        ...

    TASKS = {t.name: t for t in (BlockPush(), PegInsertion(), Slide())}

The simulated box push of Table I is built from :mod:`lfdt.layout`, :mod:`lfdt.envs` and
:mod:`lfdt.programmed` (torque-driven arms with joints, not this planar interface).
"""

from __future__ import annotations

from lfdt.tasks.base import PlanarTask
from lfdt.tasks.block_push import BlockPush
from lfdt.tasks.peg_insertion import PegInsertion

TASKS: dict[str, PlanarTask] = {t.name: t for t in (BlockPush(), PegInsertion())}
"""Every real-robot task by name."""
NAMES: tuple[str, ...] = tuple(TASKS)


def get(name: str) -> PlanarTask:
    """The task called ``name``; ValueError naming the known ones otherwise."""
    try:
        return TASKS[name]
    except KeyError:
        raise ValueError(f"unknown task {name!r}; expected one of {NAMES}") from None
