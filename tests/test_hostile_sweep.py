"""Hostile input to ``python -m lfdt.sweep``: each case ends in exit code 2 and one line naming what was wrong, before
any work, within seconds. A new case is one row of :data:`CASES`."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
import services

from lfdt import reach

PORT = services.free_port()
"""A port of 127.0.0.1 nothing listens on (bound, then released)."""

CASES = [
    # (id, arguments, environment, what the one line must say)
    ("ray-refused", ["--address", f"127.0.0.1:{PORT}"], {}, f"the Ray cluster (--address or RAY_ADDRESS) at "
                                                            f"127.0.0.1:{PORT} does not accept a connection"),
    ("ray-client-url", ["--address", f"ray://127.0.0.1:{PORT}"], {}, f"Ray cluster (--address or RAY_ADDRESS) at "
                                                                      f"ray://127.0.0.1:{PORT}"),
    ("ray-from-env", [], {"RAY_ADDRESS": f"127.0.0.1:{PORT}"}, "the Ray cluster (--address or RAY_ADDRESS)"),
    ("ray-port-not-a-number", ["--address", "127.0.0.1:head"], {}, "the port is not a number"),
    ("ray-blackhole", ["--address", "192.0.2.1:6379"], {}, "192.0.2.1:6379 does not accept a connection"),
    ("mlflow-server-down", [], {"MLFLOW_TRACKING_URI": f"http://127.0.0.1:{PORT}"},
     f"the MLflow tracking store (MLFLOW_TRACKING_URI) at http://127.0.0.1:{PORT}"),
    ("postgres-down", [], {"MLFLOW_TRACKING_URI": f"postgresql://lfdt:secret@127.0.0.1:{PORT}/mlflow"},
     f"postgresql://lfdt:***@127.0.0.1:{PORT}/mlflow does not accept"),
    ("s3-endpoint-down", ["--remote-url", "s3://bucket/lfdt", "--endpoint-url", f"http://127.0.0.1:{PORT}"], {},
     f"the S3 endpoint of DVC remote 'sweep' (--endpoint-url) at http://127.0.0.1:{PORT}"),
    ("endpoint-without-remote", ["--endpoint-url", f"http://127.0.0.1:{PORT}"], {},
     "--endpoint-url needs --remote-url"),
]


@pytest.mark.parametrize(("args", "env", "says"), [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_a_wrong_service_address_is_one_named_error_before_any_work(tmp_path, args, env, says):
    """Run from an empty folder: the check comes before the workspace is even read, so no stage can have run."""
    full_env = {k: v for k, v in os.environ.items() if k not in ("RAY_ADDRESS", "MLFLOW_TRACKING_URI")}
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, "-m", "lfdt.sweep", *args], cwd=tmp_path, env={**full_env, **env},
                          capture_output=True, text=True, timeout=120)
    took = time.monotonic() - t0
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert len(lines) == 1 and lines[0].startswith("error: ") and says in lines[0], proc.stderr
    assert "secret" not in proc.stderr + proc.stdout
    assert not any(tmp_path.iterdir()), "the sweep wrote into the workspace before failing"
    # a guard against a hang of minutes (the clients' own retries), not a speed test: the check waits 5 s at most
    assert took < 60, f"took {took:.0f} s"


def test_host_port_reads_every_address_form():
    assert reach.host_port("head:6379") == ("head", 6379)
    assert reach.host_port("ray://10.0.0.1:10001") == ("10.0.0.1", 10001)
    assert reach.host_port("http://[::1]:5000/path") == ("::1", 5000)
    assert reach.host_port("https://mlflow.example.org") == ("mlflow.example.org", 443)
    assert reach.host_port("postgresql+psycopg2://u:p@db/mlflow") == ("db", 5432)
    assert reach.host_port("head", default_port=6379) == ("head", 6379)
    with pytest.raises(ValueError, match="names no host:port"):
        reach.host_port("head")
    assert reach.redact("postgresql://u:p4ss@db/x") == "postgresql://u:***@db/x"
    assert reach.redact("http://db:5000") == "http://db:5000"


def test_a_service_that_listens_passes():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen(1)
        reach.check(f"127.0.0.1:{s.getsockname()[1]}", "a test server", timeout=2)
    with pytest.raises(reach.Unreachable, match=f"a test server at 127.0.0.1:{PORT} does not accept"):
        reach.check(f"127.0.0.1:{PORT}", "a test server", timeout=2)


def test_a_repo_url_that_looks_like_an_option_is_a_url_to_git(tmp_path):
    """A chain clones ``--repo-url`` after ``--``: a value that starts with a dash is a repository git cannot find,
    never an option it runs (``--upload-pack`` names a program)."""
    from lfdt.sweep.chain import ChainSpec, Remote, run_chain

    marker = tmp_path / "ran"
    spec = ChainSpec(name="x", stages=("a",), shared=(), repo_url=f"--upload-pack=touch {marker}", commit="HEAD",
                     params_yaml="", remote=Remote("sweep"), workdir=str(tmp_path / "work"))
    result = run_chain(spec)
    assert not result.ok and "git clone" in result.error and not marker.exists()
    assert f"repository '{spec.repo_url}' does not exist" in result.log_tail, result.log_tail


ROOT = Path(__file__).resolve().parents[1]
PARAMS = (ROOT / "params.yaml").read_bytes()

# (id, params.yaml's bytes (None: the folder is not the project's), arguments, what the one line must say)
PROJECT_CASES = [
    ("params-not-utf8", PARAMS.replace(b"device: cpu", b"device: c\xffpu", 1), ["--list"],
     "params file {tmp}/params.yaml: line 1: byte 0xff"),
    ("params-key-twice", PARAMS.replace(b"device: cpu", b"device: cpu\ndevice: cuda", 1), ["--list"],
     "{tmp}/params.yaml is not valid YAML: line 2, column 1: found the key 'device' a second time"),
    ("params-key-twice-set", PARAMS.replace(b"device: cpu", b"device: cpu\ndevice: cuda", 1),
     ["--list", "-S", "translator.lambda_dyn=1,2"], "found the key 'device' a second time"),
    ("not-the-project", None, ["--list"], "{tmp} is not the project's folder (it has no dvc.yaml and .dvc/)"),
    ("set-unknown-twin-task", PARAMS, ["--list", "-S", "twin.tasks=[peg_insert]"],
     "--set twin.tasks: params.yaml twin.tasks: unknown task(s) ['peg_insert']"),
    ("cpus-not-a-number", PARAMS, ["--list", "--cpus-per-chain", "nan"],
     "argument --cpus-per-chain: nan is not a positive finite number"),
]


@pytest.mark.parametrize(("params", "args", "says"), [c[1:] for c in PROJECT_CASES],
                         ids=[c[0] for c in PROJECT_CASES])
def test_a_hostile_project_or_params_is_one_named_error(tmp_path, params, args, says):
    """params.yaml and the folder are checked as the stages check them, before the plan is read."""
    if params is not None:
        (tmp_path / "params.yaml").write_bytes(params)
        (tmp_path / "dvc.yaml").write_bytes((ROOT / "dvc.yaml").read_bytes())
        (tmp_path / ".dvc").mkdir()
    proc = subprocess.run([sys.executable, "-m", "lfdt.sweep", *args], cwd=tmp_path, capture_output=True, text=True,
                          timeout=120)
    lines = [line for line in proc.stderr.strip().splitlines() if not line.startswith(("usage:", " "))]
    assert proc.returncode == 2, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert len(lines) == 1 and says.format(tmp=tmp_path) in lines[0], proc.stderr
    assert "Traceback" not in proc.stderr
