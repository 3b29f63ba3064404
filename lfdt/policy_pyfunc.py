"""The code of every policy model (MLflow "models from code", :mod:`lfdt.policy_models`): MLflow runs this file to
load a model, so it only names the model class.

A process that loads the model with ``lfdt`` imported first (``python -m lfdt.robot deploy``) keeps the numeric pin
(:mod:`lfdt.numerics`). ``mlflow models predict`` and ``mlflow models serve`` load numpy before this file runs; then
the pin cannot take effect and the policy runs on the CPU's own kernels (``LFDT_NUMERICS=native``): actions equal
the pipeline's up to float rounding. Export the pinned variables (``python -c "import lfdt.numerics as n;
print(n.PINNED_ENV)"``) before starting MLflow to keep the same bits.

Under ``mlflow models predict`` (``--env-manager local``: the model runs in the CLI's process), an input MLflow or
the model refuses (malformed JSON, a NaN observation: :func:`lfdt.policy_models.observations`) ends in one line
``error: --input-path FILE: ...`` and exit code 2 instead of a traceback (:func:`one_line_input_errors`).
"""

import os
import sys
import warnings

import mlflow

try:
    from lfdt.policy_models import PolicyModel
except ImportError as e:  # lfdt.numerics.NumericsError: numpy came first (MLflow's own process)
    if type(e).__name__ != "NumericsError":
        raise
    warnings.warn(f"{e}; the policy model runs with LFDT_NUMERICS=native", stacklevel=1)
    os.environ["LFDT_NUMERICS"] = "native"
    for name in [m for m in sys.modules if m == "lfdt" or m.startswith("lfdt.")]:
        del sys.modules[name]
    from lfdt.policy_models import PolicyModel



def _is_predict_cli(argv: list[str]) -> bool:
    """Whether this process is ``mlflow models predict`` (the console script, or ``python -m mlflow``), or the
    process in which it predicts with another ``--env-manager`` (whose failure MLflow's CLI then reports itself)."""
    if not argv:
        return False
    prog = os.path.basename(argv[0])
    if prog == "_mlflow_pyfunc_backend_predict.py":
        return True
    is_mlflow = prog == "mlflow" or (prog == "__main__.py" and os.path.basename(os.path.dirname(argv[0])) == "mlflow")
    return is_mlflow and argv[1:3] == ["models", "predict"]


def one_line_input_errors(argv: list[str]) -> bool:
    """In ``mlflow models predict`` only, print an uncaught MlflowException about the input (error codes
    BAD_REQUEST, INVALID_PARAMETER_VALUE: MLflow's parse of the request, the model's check of the observations) as
    ``error: <input>: <its first line>`` and exit 2, as lfdt's own commands do; anything else keeps Python's
    traceback. MLflow's CLI raises these out of click, which prints a traceback and exits 1. Returns whether the hook
    was installed."""
    if not _is_predict_cli(argv):
        return False
    source = next((f"{a} {b}" for a, b in zip(argv, argv[1:]) if a in ("-i", "--input-path")), "the input (stdin)")
    previous = sys.excepthook

    def hook(kind, err, tb) -> None:
        from mlflow.exceptions import MlflowException

        if isinstance(err, MlflowException) and err.error_code in ("BAD_REQUEST", "INVALID_PARAMETER_VALUE"):
            first = (err.message.strip().splitlines() or [kind.__name__])[0]
            print(f"error: {source}: {first}", file=sys.stderr, flush=True)
            sys.stdout.flush()
            os._exit(2)  # an excepthook cannot choose the exit code; nothing is left to clean up in this CLI
        previous(kind, err, tb)

    sys.excepthook = hook
    return True


one_line_input_errors(sys.argv)
mlflow.models.set_model(PolicyModel())
