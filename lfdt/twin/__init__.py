"""The MuJoCo twin of the paper's two real tasks and the LfDT pipeline run on it (or on robot recordings).

:mod:`lfdt.twin.env` is the simulated scene, :mod:`lfdt.twin.programs` the robots' programmed motions and the
scripted person, :mod:`lfdt.twin.pipeline` the recordings, training and evaluation the DVC stages run. The tasks
themselves are in :mod:`lfdt.tasks`.
"""

METHODS: tuple[str, ...] = ("bc_no_translation", "lfdt")
"""The methods run on the real-robot tasks (records of :mod:`lfdt.methods`), as in the paper's §IV-E."""
PAPER_REAL: dict[str, dict[str, tuple[int, int]]] = {
    "block_push": {"lfdt": (10, 10), "bc_no_translation": (10, 10)},
    "peg_insertion": {"lfdt": (8, 10), "bc_no_translation": (2, 10)}}
"""The paper's real-robot results (successes, trials) by task and method."""
