"""Every task, one module (or package) each, behind one small interface (:class:`lfdt.tasks.base.Task`).

* :mod:`lfdt.tasks.box_push`: the simulated dual-arm box push of Table I (arms with joints, torque commands);
* :mod:`lfdt.tasks.block_push`, :mod:`lfdt.tasks.peg_insertion`: the real-robot tasks of §IV-E, planar
  (:class:`lfdt.tasks.base.PlanarTask`), run in the MuJoCo twin (:mod:`lfdt.twin`) or on the robots
  (:mod:`lfdt.robot`).

:mod:`lfdt.tasks.registry` looks a task up by name and imports its module only then. This file stays empty on
purpose: importing any task module runs it first, so every line here would be code every task's DVC stages depend
on.
"""
