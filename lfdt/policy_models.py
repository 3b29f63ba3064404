"""Trained BC policies as MLflow models: logged into the run that trained them, registered, loaded back by URI.

Every policy the pipeline trains becomes an MLflow pyfunc model (``stages/register_policies.py``):

* its files (one state dict and one JSON config per member, :meth:`lfdt.bc.BCPolicy.save`) are the model's
  artifacts, so the resolved config lies beside the weights; the config is also the model's metadata;
* its signature names domain Y's state columns (input) and action columns (output), and its input example is one
  observation of the task in Y;
* it is registered under :func:`registered_name` (task, method and, for Table I, demo count), one version per
  seed, with the alias ``seed<N>``: ``models:/box_push.lfdt.d50@seed100``, ``models:/block_push.lfdt@seed3``.

The model's code is :mod:`lfdt.policy_pyfunc` (MLflow's "models from code": nothing is pickled). Loading needs
this package installed (``make setup``). :func:`policy_from_uri` turns a ``models:/`` (or ``runs:/``) URI back into a
:class:`lfdt.bc.BCPolicy`, for the robot's and the twin's ``deploy``.
"""

from __future__ import annotations

import json
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import mlflow
import numpy as np
import pandas as pd

from lfdt import bc
from lfdt.tasks import registry

CONFIG_ARTIFACT = "lfdt_model"
"""The artifact holding the model's own settings (task, method, demos, seed, action clip), a JSON file: MLflow's
``model_config`` would be logged as params of the training run, where the twin's two methods would clash."""
MODEL_CODE = Path(__file__).with_name("policy_pyfunc.py")
URI_SCHEMES = ("models:/", "runs:/")
"""Where :func:`policy_from_uri` takes an MLflow URI instead of a folder."""


def registered_name(task: str, method: str, demos: int | None = None) -> str:
    """The registry name of a policy: ``<task>.<method>.d<demos>`` (Table I), ``<task>.<method>`` (the twin's,
    whose demonstrations are the recordings)."""
    return f"{task}.{method}" + (f".d{demos}" if demos is not None else "")


def alias(seed: int) -> str:
    """The alias of a seed's version."""
    return f"seed{seed}"


def is_uri(location: str | Path) -> bool:
    """Whether ``location`` is an MLflow model URI rather than a folder."""
    return str(location).startswith(URI_SCHEMES)


class PolicyModel(mlflow.pyfunc.PythonModel):
    """The pyfunc model: a saved :class:`lfdt.bc.BCPolicy` acting on a DataFrame of domain Y observations.

    Its settings (:data:`CONFIG_ARTIFACT`): ``task`` (registry name), ``method``, ``demos``, ``seed`` and
    ``action_bounds`` (``[low, high]`` or None: the clip the pipeline applies). MLflow calls :meth:`load_context`
    once and :meth:`predict` per request.
    """

    def load_context(self, context: Any) -> None:
        """Load the policy's members from the model's artifacts (``weights_only=True``)."""
        if CONFIG_ARTIFACT not in context.artifacts:
            raise ValueError(f"the model has no {CONFIG_ARTIFACT!r} artifact: it was not logged by lfdt.policy_models")
        cfg = json.loads(Path(context.artifacts[CONFIG_ARTIFACT]).read_text())
        layout = registry.get(cfg["task"]).layout
        bounds = cfg.get("action_bounds")
        self.task, self.method = cfg["task"], cfg.get("method")
        self.policy, self.config = bc.BCPolicy.load(Path(context.artifacts["policy"]), layout,
                                                    tuple(bounds) if bounds is not None else None)
        self.state_columns = layout.state_columns("Y")
        self.action_columns = layout.action_columns("Y")

    def predict(self, context: Any, model_input: pd.DataFrame, params: Mapping[str, Any] | None = None) -> pd.DataFrame:
        """One action row per observation row; the columns are Y's action columns."""
        frame = pd.DataFrame(model_input)
        missing = [c for c in self.state_columns if c not in frame.columns]
        if missing:
            raise ValueError(f"the observations lack the state columns {missing} of {self.task}'s domain Y "
                             f"(expected {self.state_columns})")
        obs = observations(frame, self.state_columns, self.task)
        actions = np.stack([self.policy(y) for y in obs]) if len(obs) else np.zeros((0, len(self.action_columns)))
        return pd.DataFrame(actions, columns=self.action_columns)


def observations(frame: pd.DataFrame, columns: list[str], task: str) -> np.ndarray:
    """The ``columns`` of ``frame`` as floats, every one finite: a NaN or an infinity (a sensor that dropped out, a
    null in a JSON request) would come back as NaN actions, which a robot cannot take. MlflowException (MLflow's
    server answers it with 400) naming the first bad cell's column and row otherwise."""
    from mlflow.exceptions import MlflowException

    part = frame[columns]
    try:
        obs = part.to_numpy(dtype=np.float64)
    except (TypeError, ValueError):
        numeric = part.apply(pd.to_numeric, errors="coerce")
        bad = numeric.isna() & part.notna()
        row, col = np.argwhere(bad.to_numpy())[0]
        raise MlflowException.invalid_parameter_value(
            f"observation row {row}, column {columns[col]!r}: {part.iat[row, col]!r} is not a number; expected "
            f"finite numbers in {task}'s state columns {columns}") from None
    bad = ~np.isfinite(obs)
    if bad.any():
        row, col = np.argwhere(bad)[0]
        raise MlflowException.invalid_parameter_value(
            f"observation row {row}, column {columns[col]!r} is {obs[row, col]} ({int(bad.sum())} cells of "
            f"{bad.size} are not finite); expected finite numbers in {task}'s state columns")
    return obs


def input_example(task: str) -> pd.DataFrame:
    """One observation of ``task`` in domain Y, as the model's input example (reset seed 0, outside every block of
    :mod:`lfdt.seeding`: it is no evaluation start state)."""
    env = registry.get(task).make_env("Y")
    try:
        obs, _ = env.reset(seed=0)
    finally:
        env.close()
    return pd.DataFrame([np.asarray(obs, dtype=np.float64)], columns=registry.get(task).layout.state_columns("Y"))


def log_policy(policy_dir: Path, *, run_id: str, task: str, method: str, seed: int, demos: int | None,
               action_bounds: tuple[float, float] | None, example: pd.DataFrame,
               requirements: list[str]) -> dict[str, Any]:
    """Log the policy saved in ``policy_dir`` as a model of the run ``run_id`` (the run that trained it), register it
    and point the seed's alias at the new version; returns name, version, alias, URI and run id."""
    from mlflow.models import infer_signature

    policy, config = bc.BCPolicy.load(policy_dir, registry.get(task).layout, action_bounds)
    actions = pd.DataFrame([policy(y) for y in example.to_numpy()],
                           columns=registry.get(task).layout.action_columns("Y"))
    name = registered_name(task, method, demos)
    model_config = {"task": task, "method": method, "demos": demos, "seed": seed,
                    "action_bounds": list(action_bounds) if action_bounds is not None else None}
    client = mlflow.MlflowClient()
    with tempfile.TemporaryDirectory() as tmp, mlflow.start_run(run_id=run_id):
        settings = Path(tmp) / f"{CONFIG_ARTIFACT}.json"
        settings.write_text(json.dumps(model_config, indent=2))
        info = mlflow.pyfunc.log_model(
            name=method, python_model=str(MODEL_CODE),
            artifacts={"policy": str(policy_dir), CONFIG_ARTIFACT: str(settings)},
            signature=infer_signature(example, actions), input_example=example, pip_requirements=requirements,
            metadata={"lfdt": model_config, "lfdt_config": config}, registered_model_name=name)
    version = str(info.registered_model_version)
    client.set_registered_model_alias(name, alias(seed), version)
    for key, value in model_config.items():
        if value is not None and key != "action_bounds":
            client.set_model_version_tag(name, version, f"lfdt.{key}", str(value))
    return {"name": name, "version": version, "alias": alias(seed), "uri": f"models:/{name}@{alias(seed)}",
            "run_id": run_id, "task": task, "method": method, "demos": demos, "seed": seed}


def policy_from_uri(uri: str, task: str, method: str) -> bc.BCPolicy:
    """The policy behind a ``models:/`` or ``runs:/`` URI, checked to be ``task``'s ``method``; ValueError naming
    the model's own task and method otherwise. The registry is the project's tracking store
    (:func:`lfdt.mlflow_runs.tracking_uri`: ``MLFLOW_TRACKING_URI``, else the workspace's mlflow.db), or
    ``MLFLOW_REGISTRY_URI`` where set; either not answering is a ValueError naming it within seconds
    (:func:`lfdt.mlflow_runs.check_tracking_uri`), where MLflow's client would retry for minutes."""
    import os

    from lfdt.mlflow_runs import TrackingUnavailable, bounded_http, check_tracking_uri, tracking_uri

    store = tracking_uri()
    try:
        check_tracking_uri(store)
        registry_uri = os.environ.get("MLFLOW_REGISTRY_URI")
        if registry_uri and registry_uri != store:
            try:
                check_tracking_uri(registry_uri)
            except TrackingUnavailable as err:  # the same checks, for the other variable
                raise TrackingUnavailable(str(err).replace("MLFLOW_TRACKING_URI", "MLFLOW_REGISTRY_URI")) from None
    except TrackingUnavailable as err:
        raise ValueError(str(err)) from None
    mlflow.set_tracking_uri(store)
    with bounded_http():  # a registry answering 5xx to the model's lookup: seconds, not minutes of retries
        model = mlflow.pyfunc.load_model(uri)
    inner = model.unwrap_python_model()
    if not isinstance(inner, PolicyModel):
        raise ValueError(f"{uri} is not an lfdt policy model (logged by lfdt.policy_models)")
    if (inner.task, inner.method) != (task, method):
        raise ValueError(f"{uri} is the {inner.method} policy of {inner.task}, not the {method} policy of {task}")
    return inner.policy
