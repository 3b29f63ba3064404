"""The MuJoCo twin of the paper's two real tasks and the LfDT pipeline run on it (or on robot recordings).

:mod:`lfdt.twin.collect`, :mod:`lfdt.twin.train` and :mod:`lfdt.twin.evaluate` are the jobs of the DVC stages
``twin_collect``, ``twin_train`` and ``twin_evaluate`` (:mod:`lfdt.twin.common` what they share). The scene
(:mod:`lfdt.tasks.planar_env`), the programmed robots and the scripted person (:mod:`lfdt.tasks.demonstrators`) belong
to the tasks (:mod:`lfdt.tasks`); the hardware-free rig and the recorder to :mod:`lfdt.rig`.
"""

TWIN_METHODS: tuple[str, ...] = ("bc_no_translation", "lfdt")
"""The methods run on the real-robot tasks (names of records in :data:`lfdt.methods.METHODS`), as in the paper's
§IV-E."""
PAPER_REAL: dict[str, dict[str, tuple[int, int]]] = {
    "block_push": {"lfdt": (10, 10), "bc_no_translation": (10, 10)},
    "peg_insertion": {"lfdt": (8, 10), "bc_no_translation": (2, 10)}}
"""The paper's real-robot results (successes, trials) by task and method."""
