"""DVC stage: check what every later stage reads from outside the data, before `dvc repro` runs (and so removes the
outputs of) any of them: params.yaml is valid and complete, what a stage would refuse in valid params
(:func:`check_runnable`: the torch device), and the tracking store (MLFLOW_TRACKING_URI, or the workspace's
mlflow.db) can be used: a database file is read whole, a server answers a real query. A problem is one line and exit
2 while every earlier output is still in place. DVC runs it when params.yaml or its code changes (and with -f); it
tracks no environment variable, so a new MLFLOW_TRACKING_URI alone is checked by each stage as it starts.

The file it writes says only that the check passed, the same bytes whatever the params: a later stage depends on it
for the order of the DAG, and is rerun for its own params, never for this file."""

from lfdt import mlflow_runs, parallel, stage
from lfdt.config import Params
from lfdt.files import write_atomic
from lfdt.reach import redact
from lfdt.rendering import check_videos
from lfdt.tasks import registry
from lfdt.tasks.box_push.env import check_start_reachable
from lfdt.twin.common import check_real_recordings

PASSED = "params and tracking store checked (stages/preflight.py)\n"
"""The whole of the output: constant, so that no stage downstream reruns because this one did."""


def check_runnable(p: Params) -> None:
    """What a stage would refuse in params that lfdt.config accepts (every value valid, every key present): the
    torch device missing on this machine (the training stages' own check, :func:`lfdt.nets.torch_device`), a box
    start an arm cannot reach (the environment's, at whichever reset drew it), a twin task name the registry does not
    know (the twin stages' own check), with twin.backend 'real', a recording of the robots that is not there or not
    one recording (twin_collect's) and, when videos are asked for, a MUJOCO_GL with which MuJoCo cannot render
    (evaluate's and twin_evaluate's, at their first frame). So this stage lists every task's code among its deps
    (tests/test_dvc_deps.py) and reruns, in seconds, when one changes; its output stays the same bytes, so no stage
    below reruns for it."""
    check_start_reachable(p.env)
    registry.check_twin_names(p.twin)
    if p.twin.backend == "real":  # the robots' recordings are the twin's first input
        check_real_recordings(p.twin)
    check_videos(p.evaluation.videos, "evaluation.videos")
    if p.twin.backend == "sim":
        check_videos(p.twin.videos, "twin.videos")
    if p.device != "cpu":  # torch loads in seconds: only when there is a device to look for
        from lfdt.nets import torch_device

        torch_device(p.device)


def run() -> None:
    args = stage.parser(__doc__, {"out": "the file that says the checks passed"}).parse_args()
    check_runnable(stage.params(args.params))
    uri = mlflow_runs.tracking_uri()
    mlflow_runs.check_tracking_uri(uri, thorough=True)  # a store cut short answers no query
    mlflow_runs.experiment_name()  # LFDT_MLFLOW_EXPERIMENT: one the store can keep
    mlflow_runs.check_store_answers(uri)  # a server's /health can answer while its API fails
    parallel.start_method()  # LFDT_WORKER_START: how the matrix stages start their workers
    write_atomic(args.out, lambda tmp: tmp.write_text(PASSED))
    print(f"preflight: {args.params} valid; tracking store {redact(uri)} usable")


if __name__ == "__main__":
    stage.main(run)
