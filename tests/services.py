"""Servers a test starts for itself on 127.0.0.1 and stops by process id, also when the test fails: PostgreSQL, an
S3 server (moto), an MLflow tracking server on both, and a Ray head with worker nodes."""

from __future__ import annotations

import contextlib
import glob
import os
import pwd
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from collections.abc import Callable, Iterator
from pathlib import Path

BIN = Path(sys.executable).parent
PG_USER = "lfdtpg"
"""The system user PostgreSQL runs as when the tests run as root (initdb refuses root)."""
S3_ENV = {"AWS_ACCESS_KEY_ID": "testing", "AWS_SECRET_ACCESS_KEY": "testing", "AWS_DEFAULT_REGION": "us-east-1"}
"""Credentials of the test S3 server (it accepts any)."""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for(ok: Callable[[], bool], what: str, proc: subprocess.Popen | None = None, timeout: float = 60.0,
             log: Path | None = None) -> None:
    """Poll ``ok`` until it holds; fail naming ``what`` (with the end of its log) on timeout or when it exits."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc is not None and proc.poll() is not None:
            break
        with contextlib.suppress(Exception):
            if ok():
                return
        time.sleep(0.3)
    tail = log.read_text()[-3000:] if log and log.exists() else ""
    state = f"exited with {proc.returncode}" if proc is not None and proc.poll() is not None else "timed out"
    raise RuntimeError(f"{what} did not start ({state}):\n{tail}")


def stop(proc: subprocess.Popen, timeout: float = 10.0) -> None:
    """Stop a server started with ``start_new_session``: its whole process group, by the leader's id."""
    stop_all([proc], timeout)


def stop_all(procs: list[subprocess.Popen], timeout: float = 10.0) -> None:
    """Stop several servers at once (each by its process group): SIGTERM to all, ``timeout`` seconds for them to go,
    then SIGKILL to what is left."""
    for sig in (signal.SIGTERM, signal.SIGKILL):
        alive = [p for p in procs if p.poll() is None or _group_alive(p.pid)]
        for p in alive:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(p.pid, sig)
        deadline = time.monotonic() + timeout
        while alive and time.monotonic() < deadline:
            for p in alive:
                p.poll()  # reaps a leader that exited, so its group can count as gone
            alive = [p for p in alive if _group_alive(p.pid)]
            time.sleep(0.1)
    for p in procs:
        with contextlib.suppress(subprocess.TimeoutExpired):
            p.wait(timeout=5)


def _group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _popen(args: list[str], log: Path, env: dict[str, str] | None = None, **kw) -> subprocess.Popen:
    fh = open(log, "ab")  # noqa: SIM115 - the server holds it for its life
    return subprocess.Popen(args, stdout=fh, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                            start_new_session=True, env={**os.environ, **(env or {})}, **kw)


REQUIRE_ENV = "LFDT_REQUIRE_SERVICES"
"""Set to 1 (``.ci/run`` does) to fail, not skip, a test whose server programs are missing."""


def require_postgres() -> None:
    """Skip the calling test, naming what is missing, when PostgreSQL's server programs are not installed (``make
    test`` installs them where it can: ``tools/test_prereqs.sh``); with ``LFDT_REQUIRE_SERVICES=1``, fail instead."""
    try:
        _pg_bin("initdb")
        _pg_bin("postgres")
    except RuntimeError as e:
        if os.environ.get(REQUIRE_ENV) == "1":
            raise
        import pytest

        pytest.skip(f"{e}; skipped (set {REQUIRE_ENV}=1 to fail instead)")


def _pg_bin(name: str) -> str:
    found = shutil.which(name) or next(iter(sorted(glob.glob(f"/usr/lib/postgresql/*/bin/{name}"), reverse=True)),
                                       None)
    if not found:
        raise RuntimeError(f"PostgreSQL's {name} is not installed (Debian: apt-get install postgresql; `make test` "
                           f"installs it when run as root with apt-get)")
    return found


@contextlib.contextmanager
def postgres(logs: Path) -> Iterator[str]:
    """A PostgreSQL server with a database 'mlflow'; yields its SQLAlchemy URI."""
    user = None
    if os.geteuid() == 0:
        try:
            pwd.getpwnam(PG_USER)
        except KeyError:
            subprocess.run(["useradd", "--system", "--no-create-home", "--shell", "/usr/sbin/nologin", PG_USER],
                           check=True)
        user = PG_USER
    data = Path(tempfile.mkdtemp(prefix="lfdt-pg-"))  # not under pytest's tmp: that is root's only
    if user:
        shutil.chown(data, user, user)
    port = free_port()
    subprocess.run([_pg_bin("initdb"), "-D", str(data / "db"), "-U", "lfdt", "--auth=trust", "-E", "UTF8"],
                   check=True, capture_output=True, user=user, cwd=data)
    proc = _popen([_pg_bin("postgres"), "-D", str(data / "db"), "-p", str(port), "-k", str(data),
                   "-c", "listen_addresses=127.0.0.1", "-c", "fsync=off"], logs / "postgres.log", user=user, cwd=data)
    try:
        import psycopg2

        def connect():
            return psycopg2.connect(host="127.0.0.1", port=port, user="lfdt", dbname="postgres")

        wait_for(lambda: connect().close() is None, "PostgreSQL", proc, log=logs / "postgres.log")
        conn = connect()
        conn.autocommit = True
        with conn.cursor() as cur:
            cur.execute("CREATE DATABASE mlflow")
        conn.close()
        yield f"postgresql+psycopg2://lfdt@127.0.0.1:{port}/mlflow"
    finally:
        stop(proc)
        shutil.rmtree(data, ignore_errors=True)


@contextlib.contextmanager
def s3_server(logs: Path, bucket: str) -> Iterator[str]:
    """A moto S3 server with one bucket; yields its endpoint URL (use with :data:`S3_ENV`)."""
    port = free_port()
    proc = _popen([str(BIN / "moto_server"), "-H", "127.0.0.1", "-p", str(port)], logs / "s3.log", env=S3_ENV)
    url = f"http://127.0.0.1:{port}"
    try:
        wait_for(lambda: urllib.request.urlopen(url, timeout=2).close() is None, "the S3 server", proc,
                 log=logs / "s3.log")
        import boto3

        boto3.client("s3", endpoint_url=url, **_boto_kwargs()).create_bucket(Bucket=bucket)
        yield url
    finally:
        stop(proc)


def _boto_kwargs() -> dict[str, str]:
    return {"aws_access_key_id": S3_ENV["AWS_ACCESS_KEY_ID"], "aws_secret_access_key": S3_ENV["AWS_SECRET_ACCESS_KEY"],
            "region_name": S3_ENV["AWS_DEFAULT_REGION"]}


@contextlib.contextmanager
def mlflow_server(logs: Path, backend_uri: str, artifacts: str, s3_endpoint: str) -> Iterator[str]:
    """An MLflow tracking server on a database, artifacts proxied to S3; yields its URL."""
    port = free_port()
    env = {**S3_ENV, "MLFLOW_S3_ENDPOINT_URL": s3_endpoint}
    proc = _popen([str(BIN / "mlflow"), "server", "--backend-store-uri", backend_uri, "--artifacts-destination",
                   artifacts, "--host", "127.0.0.1", "--port", str(port), "--workers", "1"],
                  logs / "mlflow.log", env=env)
    url = f"http://127.0.0.1:{port}"
    try:
        wait_for(lambda: urllib.request.urlopen(f"{url}/health", timeout=2).close() is None, "the MLflow server",
                 proc, timeout=120, log=logs / "mlflow.log")
        yield url
    finally:
        stop(proc)


@contextlib.contextmanager
def ray_cluster(logs: Path, workers: int = 1, env: dict[str, str] | None = None) -> Iterator[str]:
    """A Ray head and ``workers`` worker nodes, one CPU each, on 127.0.0.1; yields the head's address."""
    port = free_port()
    temp = Path(tempfile.mkdtemp(prefix="ray", dir="/tmp"))  # Ray's socket paths must stay short
    common = ["--block", "--node-ip-address", "127.0.0.1", "--num-cpus", "1", "--num-gpus", "0",
              "--object-store-memory", str(80 * 1024 * 1024), "--disable-usage-stats"]
    env = {"PATH": f"{BIN}{os.pathsep}{os.environ['PATH']}", "RAY_USAGE_STATS_ENABLED": "0", **(env or {})}
    address = f"127.0.0.1:{port}"
    procs = [_popen([str(BIN / "ray"), "start", "--head", "--port", str(port), "--include-dashboard", "false",
                     "--temp-dir", str(temp), *common], logs / "ray-head.log", env=env)]
    try:
        wait_for(lambda: _nodes(address) >= 1, "the Ray head", procs[0], timeout=120, log=logs / "ray-head.log")
        for i in range(workers):
            procs.append(_popen([str(BIN / "ray"), "start", "--address", address, *common],
                                logs / f"ray-worker{i}.log", env=env))
        wait_for(lambda: _nodes(address) >= 1 + workers, "the Ray worker nodes", procs[-1], timeout=120,
                 log=logs / "ray-worker0.log")
        yield address
    finally:
        stop_all(procs, timeout=3)  # nothing of a test cluster needs keeping: a short grace, then SIGKILL
        shutil.rmtree(temp, ignore_errors=True)


def _nodes(address: str) -> int:
    """Alive nodes of the cluster, asked in a separate process (a driver here would stay connected)."""
    code = (f"import ray; ray.init(address={address!r}, log_to_driver=False, logging_level='ERROR'); "
            "print(sum(n['Alive'] for n in ray.nodes()))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    return int(out.stdout.strip().splitlines()[-1]) if out.returncode == 0 and out.stdout.strip() else 0
