"""MLflow tracking for every stage run.

The default store is a sqlite database at the repository root (``mlflow.db``, an absolute URI,
git-ignored); ``MLFLOW_TRACKING_URI`` overrides it (e.g. ``http://127.0.0.1:5000``). Metrics are
buffered and sent with ``log_batch`` (one sqlite round trip costs ~4 ms, so never one call per point).
Creating the experiment (and the sqlite schema) is serialised with a file lock, so stages started at
once by ``dvc queue start -j 2`` cannot race.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import socket
import subprocess
import time
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from lfdt import inputs, lifeline, numerics
from lfdt.errors import InputError, StageError
from lfdt.files import process_alive
from lfdt.reach import Unreachable, check, redact

EXPERIMENT_ENV = "LFDT_MLFLOW_EXPERIMENT"
EXPERIMENT_KIND_TAG, EXPERIMENT_KIND = "mlflow.experimentKind", "custom_model_development"
"""The experiment's kind for MLflow's UI: model training, so that it opens on the runs table."""
PROBE_TIMEOUT_S = 5.0
"""How long a tracking server may take to answer the first request before the stage stops."""
DEFAULT_EXPERIMENT = "lfdt"
MAX_EXPERIMENT_NAME = 256
"""The longest experiment name every store keeps: MLflow's SQL stores declare ``experiments.name`` VARCHAR(256)
(PostgreSQL and MySQL refuse a longer one; MLflow's own check allows 500)."""
FIRST_QUERY_HTTP = {"MLFLOW_HTTP_REQUEST_MAX_RETRIES": "1", "MLFLOW_HTTP_REQUEST_BACKOFF_FACTOR": "1",
                    "MLFLOW_HTTP_REQUEST_BACKOFF_JITTER": "0", "MLFLOW_HTTP_REQUEST_TIMEOUT": str(int(PROBE_TIMEOUT_S))}
"""MLflow's HTTP settings for a stage's first query of a tracking server, where the user has not set them: one
retry, :data:`PROBE_TIMEOUT_S` each. MLflow's defaults (7 retries with growing pauses, 120 s each) make a server
that answers 5xx look like minutes of silence; later calls keep them, to ride out a server's restart mid-stage."""
_BATCH = 900  # MLflow accepts at most 1000 metrics per log_batch call


def project_root(start: Path | None = None) -> Path:
    """The nearest directory at or above ``start`` (default: cwd) holding dvc.yaml, else cwd."""
    here = (start or Path.cwd()).resolve()
    for d in (here, *here.parents):
        if (d / "dvc.yaml").exists():
            return d
    return here


def workspace_root() -> Path:
    """The DVC workspace whose store the runs go to.

    ``dvc exp run --temp`` and ``dvc queue`` run stages in a copy under ``<workspace>/.dvc/tmp/exps/`` that DVC
    deletes afterwards; ``DVC_ROOT`` (set by DVC) then names that copy, and the workspace is the directory that
    holds its ``.dvc``. Without DVC, the nearest directory holding dvc.yaml.
    """
    root = Path(os.environ.get("DVC_ROOT") or project_root()).resolve()
    parts = root.parts
    for i in range(len(parts) - 3):
        if parts[i:i + 3] == (".dvc", "tmp", "exps"):
            return Path(*parts[:i])
    return root


URI_CHANGES = {"?": "starts a query string", "%": "starts an escape such as %20"}
"""Characters of a folder's path that a sqlite URI cannot carry as they are: SQLAlchemy reads them as URI syntax, so
the store would be another file (and MLflow would make a folder of the path as written)."""


def tracking_uri() -> str:
    """``MLFLOW_TRACKING_URI`` if set, else an absolute sqlite URI of ``<workspace>/mlflow.db``; a workspace whose
    path holds a character of :data:`URI_CHANGES` raises TrackingUnavailable naming the folder."""
    if os.environ.get("MLFLOW_TRACKING_URI"):
        return os.environ["MLFLOW_TRACKING_URI"]
    root = workspace_root()
    for char, why in URI_CHANGES.items():
        if char in str(root):
            raise TrackingUnavailable(
                f"the project folder {root} has {char!r} in its path, which the default tracking store's URI "
                f"sqlite:///{root / 'mlflow.db'} cannot carry ({char!r} {why}): move the project to a folder "
                "without it, or set MLFLOW_TRACKING_URI=sqlite:////another/folder/mlflow.db")
    return f"sqlite:///{root / 'mlflow.db'}"


class TrackingUnavailable(InputError):
    """The tracking store named by MLFLOW_TRACKING_URI (or the workspace's mlflow.db) cannot be used."""


def experiment_name() -> str:
    """The experiment the stages log to: ``$LFDT_MLFLOW_EXPERIMENT``, else 'lfdt'; one longer than
    :data:`MAX_EXPERIMENT_NAME` characters (or with a control character) raises InputError naming the variable."""
    return inputs.env_text(EXPERIMENT_ENV, DEFAULT_EXPERIMENT, MAX_EXPERIMENT_NAME,
                           "the length of an experiment name in MLflow's tracking database")


SQLITE_HEADER = b"SQLite format 3\x00"
"""The first 16 bytes of every SQLite database file."""
DB_SCHEMES = ("postgresql", "postgres", "mysql", "mssql")
"""Database servers MLflow's SQL store talks to (``<scheme>[+driver]://...``), besides sqlite."""
DATABRICKS = ("databricks", "databricks-uc", "uc")
"""Tracking URIs of Databricks (bare, or ``databricks://<profile>``): MLflow's client finds their host itself."""


def _scheme(uri: str) -> str:
    """The URI's scheme, lower case, with its driver (``postgresql+psycopg2``); '' for a bare path."""
    return uri.split("://", 1)[0].lower() if "://" in uri else ""


def worker_modules(uri: str | None = None) -> tuple[str, ...]:
    """What :func:`stage_run` imports in a worker that logs to ``uri`` (default :func:`tracking_uri`): MLflow, and
    for a database its SQL store, MLflow's slowest import (about 1 s on a 2-core EPYC). lfdt.parallel's forkserver
    imports them once for all its workers."""
    scheme = _scheme(uri or tracking_uri()).split("+", 1)[0]
    return ("mlflow", "mlflow.store.tracking.sqlalchemy_store") if scheme in ("sqlite", *DB_SCHEMES) else ("mlflow",)


def check_tracking_uri(uri: str, timeout: float = PROBE_TIMEOUT_S, thorough: bool = False) -> None:
    """Check the tracking store ``uri`` before any run is opened; TrackingUnavailable names it and what is wrong.

    * ``sqlite:///path``: no query string (MLflow would open another, empty store), the folder exists and can be
      written, and an existing file is an SQLite database that answers a query (:func:`lfdt.inputs.sqlite_answers`;
      ``thorough``: every page is read, as preflight does);
    * ``postgresql://`` and the other database servers: the driver is installed, and the server accepts a connection
      within ``timeout`` seconds (:mod:`lfdt.reach`);
    * ``http(s)://``: the server answers on /health within ``timeout`` seconds, and not with 5xx;
    * anything else (``file:`` stores, ``ftp://``, a mistyped scheme): refused, naming the schemes that work.
    """
    try:
        urlsplit(uri).port  # noqa: B018 - what every client does first, so a URL it cannot split is named here
    except ValueError as err:
        raise TrackingUnavailable(f"MLFLOW_TRACKING_URI={redact(uri)}: not a URL that can be read ({err}); e.g. "
                                  "sqlite:////absolute/path/mlflow.db or http://host:port") from None
    if uri.lower() in DATABRICKS:
        return  # MLflow's own spelling of a Databricks workspace (its CLI profile): no address to check here
    scheme = _scheme(uri)
    base = scheme.split("+")[0]
    if base in ("http", "https"):
        _check_server(uri, timeout)
    elif base == "sqlite":
        _check_sqlite(uri, thorough)
    elif base in DB_SCHEMES:
        _check_database(uri, timeout)
    elif base not in DATABRICKS:
        raise TrackingUnavailable(
            f"MLFLOW_TRACKING_URI={redact(uri)}: {'a file store' if base in ('', 'file') else f'scheme {scheme!r}'} "
            "is not a tracking store the stages can use; use sqlite:////absolute/path/mlflow.db, "
            "postgresql://user@host/db (or mysql://, mssql://) or http(s)://host:port of a tracking server")


def _check_server(uri: str, timeout: float) -> None:
    # a 4xx (a proxy, another server version) is an answer: MLflow's client takes it from there; 5xx is a server down
    inputs.http_answers(uri, f"the MLflow tracking server MLFLOW_TRACKING_URI={redact(uri)}", timeout, "/health",
                        f"start it, or unset MLFLOW_TRACKING_URI to use {workspace_root() / 'mlflow.db'}",
                        error=TrackingUnavailable)


def _sqlite_path(uri: str) -> Path:
    """The database file of ``sqlite:///rel`` or ``sqlite:////abs``, %20 and the like decoded as SQLAlchemy reads
    them ('.' for an in-memory store)."""
    from urllib.parse import unquote

    return Path(unquote(uri.split("://", 1)[1][1:]) or ".")


def _check_sqlite(uri: str, thorough: bool = False) -> None:
    if "?" in uri:
        raise TrackingUnavailable(f"MLFLOW_TRACKING_URI={uri}: a query string is not supported (MLflow would open "
                                  "another, empty store); give the database's path alone, sqlite:////path/mlflow.db")
    path = _sqlite_path(uri)
    if str(path) in (".", ":memory:"):
        raise TrackingUnavailable(f"MLFLOW_TRACKING_URI={uri}: an in-memory store keeps no run; give a file, "
                                  "sqlite:////path/mlflow.db")
    folder = path.parent
    if not folder.is_dir():
        raise TrackingUnavailable(f"MLFLOW_TRACKING_URI={uri}: the folder {folder} does not exist")
    if path.is_dir():
        raise TrackingUnavailable(f"MLFLOW_TRACKING_URI={uri}: {path} is a folder; name the database file in it, "
                                  f"sqlite:///{path / 'mlflow.db'}")
    if path.exists():
        with open(path, "rb") as fh:
            head = fh.read(len(SQLITE_HEADER))
        if head and head != SQLITE_HEADER:
            raise TrackingUnavailable(f"MLFLOW_TRACKING_URI={uri}: {path} is not an SQLite database (damaged, or "
                                      "another kind of file); move it aside and the next stage starts a new store")
        if not os.access(path, os.W_OK):
            raise TrackingUnavailable(f"MLFLOW_TRACKING_URI={uri}: {path} cannot be written")
        if head:
            inputs.sqlite_answers(path, f"MLFLOW_TRACKING_URI={uri}", thorough, error=TrackingUnavailable)
    elif not os.access(folder, os.W_OK):
        raise TrackingUnavailable(f"MLFLOW_TRACKING_URI={uri}: the folder {folder} cannot be written")


def _check_database(uri: str, timeout: float) -> None:
    from sqlalchemy.engine import make_url
    from sqlalchemy.exc import ArgumentError, NoSuchModuleError

    try:
        url = make_url(uri)
        dialect = url.get_dialect()
        dialect.import_dbapi()
    except (ArgumentError, NoSuchModuleError, ImportError) as err:
        raise TrackingUnavailable(f"MLFLOW_TRACKING_URI={redact(uri)}: its database driver cannot be loaded "
                                  f"({type(err).__name__}: {err}); install it (e.g. pip install psycopg2-binary for "
                                  "postgresql://) or name an installed one (postgresql+psycopg2://...)") from None
    if url.host is None or (dialect.driver == "pyodbc" and url.database is None):
        return  # a local socket (postgresql:///db) or an ODBC data source name: no host:port to try
    try:
        check(uri, "the MLflow tracking database (MLFLOW_TRACKING_URI)", timeout=timeout)
    except Unreachable as err:
        raise TrackingUnavailable(str(err)) from None


OUTPUT_PATHS = ("reports", "dvc.lock")
"""Tracked files the pipeline itself rewrites (metrics, plots, the lock): they do not make a commit 'dirty' (DVC
deletes a stage's outputs before it runs, so every run would look dirty)."""


def git_commit(root: Path | None = None) -> str:
    """The checked-out commit (with '-dirty' when tracked files other than the pipeline's outputs differ from it),
    or 'unknown'."""
    try:
        cwd = root or project_root()
        sha = subprocess.run(["git", "rev-parse", "HEAD"], cwd=cwd, capture_output=True, text=True,
                             check=True, timeout=10).stdout.strip()
        top = subprocess.run(["git", "rev-parse", "--show-toplevel"], cwd=cwd, capture_output=True, text=True,
                             check=True, timeout=10).stdout.strip()
        excluded = [f":(exclude){p}" for p in OUTPUT_PATHS]
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", ".", *excluded],
                               cwd=top, capture_output=True, text=True, timeout=10).stdout.strip()
        return sha + ("-dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def library_versions() -> dict[str, str]:
    """Versions of the libraries whose behaviour the results depend on."""
    from importlib.metadata import PackageNotFoundError, version

    out = {}
    for pkg in ("mujoco", "torch", "stable-baselines3", "gymnasium"):
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            out[pkg] = "not installed"
    return out


def flatten(d: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested mapping -> {'a.b.c': value}; lists become JSON strings."""
    out: dict[str, Any] = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, Mapping):
            out.update(flatten(v, key + "."))
        else:
            out[key] = json.dumps(v) if isinstance(v, list | tuple) else v
    return out


@contextlib.contextmanager
def bounded_http() -> Iterator[None]:
    """MLflow's HTTP calls inside retry little (:data:`FIRST_QUERY_HTTP`, where the user set nothing else)."""
    unset = {k: v for k, v in FIRST_QUERY_HTTP.items() if k not in os.environ}
    os.environ.update(unset)
    try:
        yield
    finally:
        for k in unset:
            os.environ.pop(k, None)


@contextlib.contextmanager
def _file_lock(path: Path) -> Iterator[None]:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def _retry(fn, attempts: int = 8):
    """Retry a store call a few times: concurrent sqlite writers can see 'database is locked'."""
    for i in range(attempts):
        try:
            return fn()
        except Exception as err:  # noqa: BLE001 - re-raised below once retries are used up
            if i == attempts - 1 or "locked" not in str(err).lower():
                raise
            time.sleep(0.2 * (i + 1))
    return None


def _first_query(uri: str, name: str):
    """An MLflow client of ``uri`` and the experiment ``name`` (None if missing): the store's first real query, whose
    failure (a server that answers /health but fails its API, a database that refuses the login) is one line."""
    import mlflow

    mlflow.set_tracking_uri(uri)
    try:
        client = mlflow.MlflowClient()  # opens a database store (its schema checked, migrated)
        with bounded_http():  # a server that fails every request: one line within seconds, not minutes
            return client, client.get_experiment_by_name(name)
    except Exception as err:  # noqa: BLE001 - any failure of the first query means the store is unusable
        first = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise TrackingUnavailable(f"the MLflow tracking store MLFLOW_TRACKING_URI={redact(uri)} cannot be read "
                                  f"({type(err).__name__}: {first})") from err


def _active(uri: str, client, exp):
    """``(client, exp)`` unless the experiment is deleted (in MLflow's UI, say): MLflow refuses every run in it, so
    TrackingUnavailable names it and the three ways on."""
    if exp is not None and exp.lifecycle_stage == "deleted":
        store = f"MLFLOW_TRACKING_URI={redact(uri)}"
        raise TrackingUnavailable(
            f"the MLflow experiment {exp.name!r} ({EXPERIMENT_ENV}, default {DEFAULT_EXPERIMENT!r}) in {store} is "
            f"deleted (id {exp.experiment_id}), and MLflow logs no run to it: restore it with `{store} mlflow "
            f"experiments restore --experiment-id {exp.experiment_id}`, remove it for good with `{store} mlflow "
            f"gc --experiment-ids {exp.experiment_id}`, or log to another with "
            f"{EXPERIMENT_ENV}=<name>")
    return client, exp


def check_store_answers(uri: str) -> None:
    """Preflight's check of a tracking store: it answers a read-only query (the experiment's lookup), not only
    /health or a TCP connection, and the experiment, if it exists, is not deleted (:func:`_active`). A new SQLite
    store (no file yet) has no experiment to look up. No experiment or run is created (an empty database gets
    MLflow's tables, as the first stage would give it)."""
    base = _scheme(uri).split("+")[0]
    if base in ("http", "https") or base in DB_SCHEMES or (base == "sqlite" and _sqlite_path(uri).is_file()):
        _active(uri, *_first_query(uri, experiment_name()))


def experiment_id(name: str | None = None) -> str:
    """Id of the experiment ``name`` (default ``$LFDT_MLFLOW_EXPERIMENT`` or 'lfdt'), created if missing."""
    import mlflow
    from mlflow.exceptions import MlflowException

    name = name or experiment_name()
    uri = tracking_uri()
    check_tracking_uri(uri)
    mlflow.set_tracking_uri(uri)
    # beside the database file as SQLAlchemy opens it (%20 decoded): the artifacts' folder is the lock's
    db = _sqlite_path(uri) if uri.startswith("sqlite:///") else None
    lock = db.with_name(db.name + ".lock") if db else None
    ctx = _file_lock(lock) if lock else contextlib.nullcontext()
    with ctx:
        client, exp = _active(uri, *_first_query(uri, name))
        if exp is None:
            # a local store keeps artifacts beside the database, whatever directory a stage runs from
            artifacts = (Path(lock.parent) / "mlartifacts").as_uri() if lock else None
            try:
                client.create_experiment(name, artifact_location=artifacts)
            except MlflowException:
                pass  # another process (e.g. on a tracking server) created it between our two calls
            exp = client.get_experiment_by_name(name)
            if exp is None:
                raise MlflowException(f"could not create or find the MLflow experiment {name!r} at {uri}")
        if exp.tags.get(EXPERIMENT_KIND_TAG) != EXPERIMENT_KIND:
            # without it MLflow 3's UI opens an experiment on its GenAI overview (traces), not on its runs
            try:
                _retry(lambda: client.set_experiment_tag(exp.experiment_id, EXPERIMENT_KIND_TAG, EXPERIMENT_KIND))
            except MlflowException:
                # two stages starting at once on a fresh tracking server both find the tag missing; the server's
                # database refuses the second insert (a unique key), which is fine once the tag holds our value
                if client.get_experiment(exp.experiment_id).tags.get(EXPERIMENT_KIND_TAG) != EXPERIMENT_KIND:
                    raise
        return exp.experiment_id


class Tracker:
    """Buffered logging into one MLflow run."""

    def __init__(self, run_id: str):
        import mlflow

        self.run_id = run_id
        self.client = mlflow.MlflowClient()
        self._buffer: list = []

    def metrics(self, values: Mapping[str, float], step: int | None = None) -> None:
        """Queue metrics (sent in batches; call :meth:`flush` or leave the run to send them)."""
        from mlflow.entities import Metric

        ts = int(time.time() * 1000)
        for k, v in values.items():
            self._buffer.append(Metric(key=k, value=float(v), timestamp=ts, step=int(step or 0)))
        if len(self._buffer) >= _BATCH:
            self.flush()

    def flush(self) -> None:
        """Send queued metrics in batches of at most 900."""
        while self._buffer:
            chunk, self._buffer = self._buffer[:_BATCH], self._buffer[_BATCH:]
            _retry(lambda c=chunk: self.client.log_batch(self.run_id, metrics=c))

    def params(self, values: Mapping[str, Any]) -> None:
        """Log (flattened) params in batches."""
        from mlflow.entities import Param

        items = [Param(k, str(v)[:6000]) for k, v in flatten(values).items()]
        for i in range(0, len(items), 90):
            _retry(lambda c=items[i:i + 90]: self.client.log_batch(self.run_id, params=c))

    def tags(self, values: Mapping[str, Any]) -> None:
        """Set run tags."""
        from mlflow.entities import RunTag

        items = [RunTag(k, str(v)) for k, v in values.items()]
        _retry(lambda: self.client.log_batch(self.run_id, tags=items))

    def artifact(self, path: str | Path, artifact_path: str | None = None) -> None:
        """Upload a small file or a directory."""
        path = Path(path)
        if path.is_dir():
            _retry(lambda: self.client.log_artifacts(self.run_id, str(path), artifact_path))
        elif path.exists():
            _retry(lambda: self.client.log_artifact(self.run_id, str(path), artifact_path))

    def dict(self, obj: Any, name: str) -> None:
        """Upload a JSON-serialisable object as an artifact file."""
        _retry(lambda: self.client.log_dict(self.run_id, obj, name))


@contextlib.contextmanager
def stage_run(stage: str, params: Mapping[str, Any], tags: Mapping[str, Any] | None = None,
              run_name: str | None = None, parent_run_id: str | None = None) -> Iterator[Tracker]:
    """One MLflow run for one stage invocation; marked FAILED if the body raises."""
    import mlflow

    exp = experiment_id()
    all_tags = {
        "lfdt.stage": stage,
        "mlflow.source.git.commit": git_commit(),
        **{f"version.{k}": v for k, v in library_versions().items()},
        **{f"lfdt.{k}": v for k, v in (tags or {}).items()},
    }
    if os.environ.get("DVC_EXP_NAME"):
        all_tags["dvc.exp_name"] = os.environ["DVC_EXP_NAME"]
    if parent_run_id:
        all_tags["mlflow.parentRunId"] = parent_run_id
    client = mlflow.MlflowClient()
    mark_killed_runs(client, exp, run_name or stage)
    all_tags.update({"lfdt.host": socket.gethostname(), "lfdt.pid": os.getpid()})
    # what the run's numbers depend on besides code and params: pinned or native numerics, and the CPU
    all_tags.update({f"lfdt.{k}": v for k, v in numerics.describe().items() if not k.startswith("env.")})
    run = _retry(lambda: client.create_run(exp, run_name=run_name or stage))
    tracker = Tracker(run.info.run_id)
    status = "FAILED"
    _OPEN_RUNS.add(run.info.run_id)
    try:
        tracker.tags(all_tags)
        tracker.params(params)
        yield tracker
        status = "FINISHED"
    finally:
        try:
            tracker.flush()
        finally:
            _retry(lambda: client.set_terminated(run.info.run_id, status=status))
            _OPEN_RUNS.discard(run.info.run_id)


_OPEN_RUNS: set[str] = set()
"""The runs this process has open: marked KILLED when it ends because its launcher is gone."""


def _kill_open_runs() -> None:
    import mlflow

    client = mlflow.MlflowClient()
    for rid in list(_OPEN_RUNS):
        with contextlib.suppress(Exception):  # ending anyway: what is not marked now, the next run of it marks
            client.set_terminated(rid, status="KILLED")


lifeline.on_orphaned(_kill_open_runs)


def mark_killed_runs(client, experiment: str, run_name: str) -> list[str]:
    """Runs named ``run_name`` still RUNNING whose process on this host is gone (a stage killed before it could
    end its run) are marked KILLED; returns their ids."""
    host = socket.gethostname()
    runs = _retry(lambda: client.search_runs([experiment], filter_string=(
        f"attributes.run_name = '{run_name}' and attributes.status = 'RUNNING'"), max_results=100))
    killed = []
    for run in runs:
        tags = run.data.tags
        if tags.get("lfdt.host") != host or not tags.get("lfdt.pid", "").isdigit():
            continue
        pid = int(tags["lfdt.pid"])
        if pid == os.getpid() or not process_alive(pid):
            _retry(lambda r=run.info.run_id: client.set_terminated(r, status="KILLED"))
            killed.append(run.info.run_id)
    return killed


def pipeline_run_name(kind: str) -> str:
    """A parent run's name: what was run (``kind``), the commit, and the DVC experiment when there is one."""
    exp = os.environ.get("DVC_EXP_NAME")
    return f"{kind} {git_commit()[:7]}" + (f" {exp}" if exp else "")


class RunNotFound(StageError):
    """A run a parent run should adopt is not in the tracking store the stage logs to."""


def require_runs(run_ids: list[str], what: str) -> list[str]:
    """The distinct ``run_ids``, in order, after checking that each names a run of the current tracking store; one
    that is missing (the store was replaced, or the stages that logged it wrote elsewhere) raises RunNotFound naming
    it, ``what`` the runs are (e.g. "behind this report") and the store."""
    import mlflow
    from mlflow.exceptions import MlflowException

    client = mlflow.MlflowClient()
    ids = list(dict.fromkeys(run_ids))
    missing, deleted = [], []
    for rid in ids:
        try:
            run = _retry(lambda r=rid: client.get_run(r))
        except MlflowException:
            missing.append(rid)
            continue
        if run.info.lifecycle_stage == "deleted":  # in MLflow's UI: MLflow then refuses every tag set on it
            deleted.append(run)
    uri = tracking_uri()
    if missing:
        raise RunNotFound(f"{len(missing)} of the {len(ids)} runs {what} are not in the tracking store "
                          f"{redact(uri)} (first: {missing[0]}): the stages that logged them wrote to another "
                          f"store; rerun them here (`dvc repro -f <stage>`), or point MLFLOW_TRACKING_URI at theirs")
    if deleted:
        first = deleted[0]
        stage = first.data.tags.get("lfdt.stage", "?")
        raise RunNotFound(f"{len(deleted)} of the {len(ids)} runs {what} were deleted in MLflow (first: "
                          f"{first.info.run_id}, '{first.info.run_name}' of stage {stage}): restore each with "
                          f"`MLFLOW_TRACKING_URI={redact(uri)} mlflow runs restore --run-id <id>`, or rerun the "
                          f"stages that logged them (`dvc repro -f -s <stage>`)")
    return ids


def adopt_children(parent_run_id: str, run_ids: list[str]) -> int:
    """Make runs children of a parent run (the MLflow UI nests them); returns how many.

    Every id must name a run of the current tracking store (:func:`require_runs`), never a silent skip, since the
    parent run would then not hold what its table was built from.
    """
    import mlflow

    client = mlflow.MlflowClient()
    ids = require_runs(run_ids, "behind this report")
    for rid in ids:
        _retry(lambda r=rid: client.set_tag(r, "mlflow.parentRunId", parent_run_id))
    return len(ids)
