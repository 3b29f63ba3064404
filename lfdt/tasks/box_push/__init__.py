"""The simulated dual-arm box push of Table I: two planar arms with joints push a box to a goal.

One module per part, so that a stage imports (and DVC reruns it for) only what it uses:

* :mod:`~lfdt.tasks.box_push.columns`: its columns (joint angles, joint velocities, end position per arm; the box);
* :mod:`~lfdt.tasks.box_push.env`: the MuJoCo scene per domain, its success rule (``info['is_success']``) and the
  replay check of translated labels;
* :mod:`~lfdt.tasks.box_push.random_motion`: random motion per domain (batched ``mujoco.rollout``);
* :mod:`~lfdt.tasks.box_push.programmed`: the robots' programmed motions of the demonstrations;
* :mod:`~lfdt.tasks.box_push.experts`: the SAC human stand-in and the demonstrations it records;
* :mod:`~lfdt.tasks.box_push.scripted`: a scripted pusher (tests and checks);
* :mod:`~lfdt.tasks.box_push.reexecute`: the ``lfdt_track`` closed-loop re-execution in Y;
* :mod:`~lfdt.tasks.box_push.task`: the task object (:class:`lfdt.tasks.base.Task`) the registry hands out.

This file stays a docstring: importing any of the modules above runs it.
"""
