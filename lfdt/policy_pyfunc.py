"""The code of every policy model (MLflow "models from code", :mod:`lfdt.policy_models`): MLflow runs this file to
load a model, so it only names the model class.

A process that loads the model with ``lfdt`` imported first (``python -m lfdt.robot deploy``) keeps the numeric pin
(:mod:`lfdt.numerics`). ``mlflow models predict`` and ``mlflow models serve`` load numpy before this file runs; then
the pin cannot take effect and the policy runs on the CPU's own kernels (``LFDT_NUMERICS=native``): actions equal
the pipeline's up to float rounding. Export the pinned variables (``python -c "import lfdt.numerics as n;
print(n.PINNED_ENV)"``) before starting MLflow to keep the same bits.
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

mlflow.models.set_model(PolicyModel())
