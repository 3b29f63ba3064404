"""Hostile services, variables and addresses (issue 38): a tracking server that answers 503, a model registry that is
down, a sweep ``--address`` that is not Ray, an ``mlflow.db`` cut short, an experiment deleted in MLflow's UI, a
project folder whose path a sqlite URI cannot carry, a too-long ``LFDT_MLFLOW_EXPERIMENT``,
``LFDT_NUMERICS=fast``, and observations `mlflow models predict` cannot act on. Each ends in exit code 2 and one
line ``error: ...`` naming the URI, variable or file, within seconds, without a traceback. A new case is one row of
:data:`CASES`.

The servers run in this process on 127.0.0.1 (threads), started once for the module and stopped also when a test
fails. Entry points run in-process in a thread that may take :data:`LIMIT_S` (a hang fails the test instead of
blocking the suite for MLflow's minutes of retries); only the import-time case starts a Python process.
"""

from __future__ import annotations

import contextlib
import dataclasses
import http.server
import io
import os
import runpy
import socket
import sqlite3
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import services

ROOT = Path(__file__).resolve().parents[1]
LIMIT_S = 10.0
"""What the issue allows a case: the error line within 10 s."""
REFUSED = services.free_port()
"""A port of 127.0.0.1 nothing listens on."""
LONG_NAME = "x" * 600
"""An experiment name longer than every store keeps (MLflow's own check allows 500, its database columns 256)."""


class _Answers503(http.server.BaseHTTPRequestHandler):
    """A tracking server whose backend is down: every request, /health included, gets 503."""

    health = 503

    def do_GET(self) -> None:  # noqa: N802 - http.server's name
        self.send_response(self.health if self.path.endswith("/health") else 503)
        self.end_headers()
        self.wfile.write(b"Service Unavailable")

    do_POST = do_GET  # noqa: N815

    def log_message(self, *args) -> None:
        pass


class _HealthyButDown(_Answers503):
    """/health says OK (it is static), every API call gets 503: MLflow's client would retry each for minutes."""

    health = 200


@contextlib.contextmanager
def _http(handler: type[http.server.BaseHTTPRequestHandler]) -> Iterator[str]:
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    server.daemon_threads = True
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        yield f"127.0.0.1:{server.server_port}"
    finally:
        server.shutdown()
        server.server_close()


@contextlib.contextmanager
def _tcp(reply: bytes | None) -> Iterator[str]:
    """A TCP service that is not Ray: it accepts, sends ``reply`` (None: nothing) and holds the connection open."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(16)
    srv.settimeout(0.2)
    stop = threading.Event()
    held: list[socket.socket] = []

    def serve() -> None:
        while not stop.is_set():
            try:
                conn, _ = srv.accept()
            except OSError:
                continue
            held.append(conn)
            if reply is not None:
                with contextlib.suppress(OSError):
                    conn.sendall(reply)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        yield f"127.0.0.1:{srv.getsockname()[1]}"
    finally:
        stop.set()
        thread.join(5)
        for conn in held:
            conn.close()
        srv.close()


@pytest.fixture(scope="module")
def addresses() -> Iterator[dict[str, str]]:
    """The services of the table by name, each host:port on 127.0.0.1."""
    with contextlib.ExitStack() as stack:
        yield {"http503": stack.enter_context(_http(_Answers503)),
               "healthy_but_down": stack.enter_context(_http(_HealthyButDown)),
               "silent": stack.enter_context(_tcp(None)),
               "garbage": stack.enter_context(_tcp(b"+OK welcome to a redis that is not Ray\r\n")),
               "refused": f"127.0.0.1:{REFUSED}"}


def half_size_db(path: Path) -> Path:
    """An SQLite store with MLflow's two first tables, cut to half its size: its header is intact."""
    con = sqlite3.connect(path)
    con.execute("CREATE TABLE experiments (experiment_id INTEGER PRIMARY KEY, name VARCHAR(256))")
    con.execute("CREATE TABLE runs (run_uuid VARCHAR(32) PRIMARY KEY, experiment_id INTEGER, name TEXT)")
    for i in range(300):  # interleaved, so that both tables have pages in the half that goes
        con.execute("INSERT INTO experiments VALUES (?, ?)", (i, f"experiment {i} " + "e" * 200))
        con.execute("INSERT INTO runs VALUES (?, ?, ?)", (f"{i:032x}", i, "r" * 200))
    con.commit()
    con.close()
    os.truncate(path, path.stat().st_size // 2)
    assert path.read_bytes()[:16] == b"SQLite format 3\x00"
    return path


def deleted_experiment_db(path: Path) -> Path:
    """An MLflow store whose experiment 'lfdt' was deleted (as in MLflow's UI): MLflow refuses every run in it."""
    import mlflow

    client = mlflow.MlflowClient(f"sqlite:///{path}")
    client.delete_experiment(client.create_experiment("lfdt"))
    return path


@dataclasses.dataclass
class Ctx:
    """What a runner gets: the test's folder, the services' addresses, its row."""

    tmp: Path
    addr: dict[str, str]
    args: list[str]


def _in_thread(fn: Callable[[], int | None]) -> tuple[int | None, str]:
    """Run an entry point in a thread with stderr captured; (exit code, stderr). A run that has not ended after
    three times :data:`LIMIT_S` is reported as a hang (its thread is left behind, a daemon)."""
    out: dict = {}
    err = io.StringIO()

    def body() -> None:
        try:
            out["code"] = fn()
        except SystemExit as e:
            out["code"] = e.code
        except BaseException as e:  # noqa: BLE001 - reported as the case's failure, with its traceback
            import traceback

            out["code"] = "raised"
            err.write("Traceback (most recent call last):\n" + "".join(traceback.format_exception(e)))

    with contextlib.redirect_stderr(err):
        thread = threading.Thread(target=body, daemon=True)
        thread.start()
        thread.join(3 * LIMIT_S)
    if thread.is_alive():
        return None, err.getvalue() + "\n(hung)"
    return out["code"], err.getvalue()


def stage_start(ctx: Ctx) -> int | None:
    """What every stage does first: open its MLflow run, inside lfdt.stage.main."""
    from lfdt import mlflow_runs, stage

    def run() -> None:
        with mlflow_runs.stage_run("probe", {}):
            pass

    stage.main(run)
    return 0


def report_adopts(ctx: Ctx) -> int | None:
    """What the report stages do with the runs behind a table (lfdt.mlflow_runs.adopt_children), after one of them was
    deleted in MLflow's UI."""
    import mlflow

    from lfdt import mlflow_runs, stage

    def run() -> None:
        with mlflow_runs.stage_run("train_bc", {}, run_name="bc-d3-s0") as kept:
            pass
        with mlflow_runs.stage_run("train_bc", {}, run_name="bc-d3-s1") as gone:
            pass
        mlflow.MlflowClient().delete_run(gone.run_id)
        with mlflow_runs.stage_run("report", {}) as parent:
            mlflow_runs.adopt_children(parent.run_id, [kept.run_id, gone.run_id])

    stage.main(run)
    return 0


def preflight(ctx: Ctx) -> int | None:
    """The preflight stage, as dvc.yaml runs it (the repository's params.yaml)."""
    argv = sys.argv
    sys.argv = [str(ROOT / "stages/preflight.py"), "--params", str(ROOT / "params.yaml"), "--out",
                str(ctx.tmp / "preflight.txt")]
    try:
        runpy.run_path(sys.argv[0], run_name="__main__")
    finally:
        sys.argv = argv
    return 0


def sweep(ctx: Ctx) -> int | None:
    from lfdt.sweep.__main__ import main

    return main(ctx.args)


def deploy(ctx: Ctx) -> int | None:
    """The twin's deploy of a registered policy (the robots' command takes the same path)."""
    from lfdt.robot.cli import main

    return main(["deploy", "--sim", "--task", "block_push", "--method", "lfdt", "--models",
                 "models:/block_push.lfdt@seed1", "--trials", "1", "--log", str(ctx.tmp / "deploy.csv")])


def views(ctx: Ctx) -> int | None:
    from lfdt.mlflow_views import main

    return main(ctx.args)


def _predict(make_error: Callable[[], BaseException]) -> int | None:
    """`mlflow models predict -i obs.json` with the model's code loaded (its hook installed), the error raised out of
    MLflow's CLI as there; os._exit (which ends the real CLI) ends the run here."""
    from lfdt import policy_pyfunc

    class Exited(BaseException):
        pass

    previous_hook, exit_ = sys.excepthook, os._exit
    try:
        assert policy_pyfunc.one_line_input_errors(["/venv/bin/mlflow", "models", "predict", "-i", "obs.json"])
        err = make_error()
        os._exit = lambda code: (_ for _ in ()).throw(Exited(code))  # type: ignore[assignment]
        try:
            sys.excepthook(type(err), err, err.__traceback__)
        except Exited as e:
            return e.args[0]
        return 1  # Python's own exit code after a traceback
    finally:
        sys.excepthook, os._exit = previous_hook, exit_


def _policy_error(row: list) -> BaseException:
    import pandas as pd

    from lfdt.policy_models import PolicyModel

    model = PolicyModel()  # what load_context sets, without a trained policy: predict must refuse before acting
    model.task, model.state_columns, model.action_columns = "box_push", ["x", "y"], ["u"]
    model.policy = lambda y: y[:1]
    try:
        model.predict(None, pd.DataFrame([row], columns=["x", "y"]))
    except Exception as e:  # noqa: BLE001 - returned to the caller as MLflow's CLI would see it
        return e
    raise AssertionError(f"the policy model acted on {row}")


def predict_nan(ctx: Ctx) -> int | None:
    return _predict(lambda: _policy_error([0.1, float("nan")]))


def predict_text(ctx: Ctx) -> int | None:
    return _predict(lambda: _policy_error([0.1, "fast"]))


def predict_malformed_json(ctx: Ctx) -> int | None:
    from mlflow.pyfunc.scoring_server import _parse_json_data

    def parse() -> BaseException:
        try:
            _parse_json_data('{"dataframe_split": {"columns": ["x", "y"], "data": [[0.1, 0.2]', None, None)
        except Exception as e:  # noqa: BLE001 - what MLflow's CLI raises
            return e
        raise AssertionError("MLflow parsed malformed JSON")

    return _predict(parse)


def script(ctx: Ctx) -> int | None:
    """A stage script in its own process (the case is about what happens while lfdt is imported)."""
    proc = subprocess.run([sys.executable, *ctx.args], cwd=ctx.tmp, env=os.environ.copy(), capture_output=True,
                          text=True, timeout=60)
    sys.stderr.write(proc.stderr)
    return proc.returncode


# (id, entry point, environment, arguments, what the one line must say); {name} is a service's host:port, {tmp}
# the test's folder
CASES = [
    ("tracking-503", stage_start, {"MLFLOW_TRACKING_URI": "http://{http503}"}, [],
     ["MLFLOW_TRACKING_URI=http://{http503}", "HTTP 503"]),
    ("tracking-503-preflight", preflight, {"MLFLOW_TRACKING_URI": "http://{http503}"}, [],
     ["MLFLOW_TRACKING_URI=http://{http503}", "HTTP 503"]),
    ("tracking-api-503", stage_start, {"MLFLOW_TRACKING_URI": "http://{healthy_but_down}"}, [],
     ["MLFLOW_TRACKING_URI=http://{healthy_but_down}", "cannot be read", "503"]),
    ("tracking-api-503-preflight", preflight, {"MLFLOW_TRACKING_URI": "http://{healthy_but_down}"}, [],
     ["MLFLOW_TRACKING_URI=http://{healthy_but_down}", "cannot be read", "503"]),
    ("tracking-uri-broken-ipv6-preflight", preflight, {"MLFLOW_TRACKING_URI": "postgresql://u:pw@[::1/db"}, [],
     ["MLFLOW_TRACKING_URI=postgresql://u:***@[::1/db", "not a URL that can be read", "Invalid IPv6 URL"]),
    ("tracking-uri-port-out-of-range", stage_start, {"MLFLOW_TRACKING_URI": "http://127.0.0.1:99999"}, [],
     ["MLFLOW_TRACKING_URI=http://127.0.0.1:99999", "not a URL that can be read", "Port out of range"]),
    ("tracking-503-sweep", sweep, {"MLFLOW_TRACKING_URI": "http://{http503}"}, [],
     ["MLFLOW_TRACKING_URI=http://{http503}", "HTTP 503"]),
    ("deploy-registry-down", deploy, {"MLFLOW_TRACKING_URI": "http://{refused}"}, [],
     ["--models models:/block_push.lfdt@seed1", "MLFLOW_TRACKING_URI=http://{refused} does not answer"]),
    ("deploy-registry-503", deploy, {"MLFLOW_TRACKING_URI": "http://{http503}"}, [],
     ["--models models:/block_push.lfdt@seed1", "MLFLOW_TRACKING_URI=http://{http503}", "HTTP 503"]),
    ("deploy-registry-uri-down", deploy, {"MLFLOW_TRACKING_URI": "sqlite:///{tmp}/mlflow.db",
                                          "MLFLOW_REGISTRY_URI": "http://{refused}"}, [],
     ["MLFLOW_REGISTRY_URI=http://{refused} does not answer"]),
    ("ray-silent", sweep, {}, ["--address", "{silent}"],
     ["--address or RAY_ADDRESS", "{silent}", "says nothing within 3 s", "expected a gRPC server"]),
    ("ray-garbage", sweep, {}, ["--address", "{garbage}"],
     ["--address or RAY_ADDRESS", "{garbage}", "+OK welcome", "expected a gRPC server"]),
    ("ray-is-http", sweep, {"RAY_ADDRESS": "ray://{http503}"}, [],
     ["--address or RAY_ADDRESS", "ray://{http503}", "answers b'", "expected a gRPC server"]),
    ("half-size-db-preflight", preflight, {"MLFLOW_TRACKING_URI": "sqlite:///{halfdb}"}, [],
     ["MLFLOW_TRACKING_URI=sqlite:///{halfdb}", "malformed"]),
    ("half-size-db-stage", stage_start, {"MLFLOW_TRACKING_URI": "sqlite:///{halfdb}"}, [],
     ["MLFLOW_TRACKING_URI=sqlite:///{halfdb}", "malformed"]),
    ("experiment-too-long", stage_start, {"MLFLOW_TRACKING_URI": "sqlite:///{tmp}/mlflow.db",
                                          "LFDT_MLFLOW_EXPERIMENT": LONG_NAME}, [],
     ["LFDT_MLFLOW_EXPERIMENT is 600 characters long", "at most 256"]),
    ("experiment-too-long-preflight", preflight, {"MLFLOW_TRACKING_URI": "sqlite:///{tmp}/mlflow.db",
                                                  "LFDT_MLFLOW_EXPERIMENT": LONG_NAME}, [],
     ["LFDT_MLFLOW_EXPERIMENT is 600 characters long", "at most 256"]),
    ("experiment-too-long-views", views, {"MLFLOW_TRACKING_URI": "sqlite:///{tmp}/mlflow.db",
                                          "LFDT_MLFLOW_EXPERIMENT": LONG_NAME}, [],
     ["LFDT_MLFLOW_EXPERIMENT is 600 characters long", "at most 256"]),
    # the experiment deleted in MLflow's UI: before, MLflow's traceback at the first stage's run, after preflight
    ("experiment-deleted", stage_start, {"MLFLOW_TRACKING_URI": "sqlite:///{deleteddb}"}, [],
     ["experiment 'lfdt' (LFDT_MLFLOW_EXPERIMENT", "is deleted (id 1)", "mlflow experiments restore --experiment-id 1",
      "mlflow gc --experiment-ids 1", "LFDT_MLFLOW_EXPERIMENT=<name>"]),
    ("experiment-deleted-preflight", preflight, {"MLFLOW_TRACKING_URI": "sqlite:///{deleteddb}"}, [],
     ["experiment 'lfdt' (LFDT_MLFLOW_EXPERIMENT", "is deleted (id 1)"]),
    # a run behind Table I deleted in MLflow's UI: before, MLflow's traceback when the report adopted it
    ("run-deleted-report", report_adopts, {"MLFLOW_TRACKING_URI": "sqlite:///{tmp}/mlflow.db"}, [],
     ["1 of the 2 runs behind this report were deleted in MLflow", "'bc-d3-s1' of stage train_bc",
      "mlflow runs restore --run-id", "dvc repro -f -s <stage>"]),
    # a project cloned into a folder whose path a sqlite URI reads as syntax: before, an error about a
    # MLFLOW_TRACKING_URI nobody set ('?'), or about a folder that does not exist ('%20' read as a space)
    ("workspace-path-query", stage_start, {"DVC_ROOT": "{tmp}/lfdt?2"}, [],
     ["the project folder {tmp}/lfdt?2 has '?'", "starts a query string", "MLFLOW_TRACKING_URI=sqlite:////"]),
    ("workspace-path-percent-preflight", preflight, {"DVC_ROOT": "{tmp}/100%20done"}, [],
     ["the project folder {tmp}/100%20done has '%'", "starts an escape"]),
    ("ui-port-taken", views, {"MLFLOW_TRACKING_URI": "sqlite:///{tmp}/mlflow.db"},
     ["--port-free", "--ui", "http://{http503}"], ["{http503} is in use", "make mlflow-ui UI_PORT="]),
    ("experiment-newline", stage_start, {"MLFLOW_TRACKING_URI": "sqlite:///{tmp}/mlflow.db",
                                         "LFDT_MLFLOW_EXPERIMENT": "lfdt\nsecond line"}, [],
     ["LFDT_MLFLOW_EXPERIMENT=", "control character"]),
    ("numerics-fast", script, {"LFDT_NUMERICS": "fast"}, [str(ROOT / "stages/preflight.py"), "--help"],
     ["LFDT_NUMERICS='fast': expected one of pinned, native"]),
    ("numerics-fast-sweep", script, {"LFDT_NUMERICS": "fast"}, ["-m", "lfdt.sweep", "--list"],
     ["LFDT_NUMERICS='fast': expected one of pinned, native"]),
    # MUJOCO_GL exported for MuJoCo's viewer on a machine without a display, or mistyped: before, a traceback at the
    # first video, after every training stage (in bc_evaluate, after its BC training)
    ("mujoco-gl-glfw-preflight", script, {"MUJOCO_GL": "glfw", "DISPLAY": "", "WAYLAND_DISPLAY": ""},
     [str(ROOT / "stages/preflight.py"), "--params", str(ROOT / "params.yaml"), "--out", "{tmp}/preflight.txt"],
     ["MUJOCO_GL='glfw': MuJoCo cannot render here", "evaluation.videos = 2", "MUJOCO_GL=egl"]),
    ("mujoco-gl-typo-train-bc", script, {"MUJOCO_GL": "elg"},
     [str(ROOT / "stages/train_bc.py"), "--params", str(ROOT / "params.yaml"), "--method", "lfdt", "--demos", "50",
      "--bc-data", "{tmp}/bc", "--dynamics-dir", "{tmp}/dyn", "--policies", "{tmp}/pol", "--reports", "{tmp}/rep"],
     ["MUJOCO_GL='elg': MuJoCo cannot render here", "invalid value", "evaluation.videos = 2"]),
    ("predict-nan", predict_nan, {}, [], ["-i obs.json", "row 0, column 'y' is nan", "finite"]),
    ("predict-text", predict_text, {}, [], ["-i obs.json", "row 0, column 'y'", "'fast' is not a number"]),
    ("predict-malformed-json", predict_malformed_json, {}, [], ["-i obs.json", "Invalid input", "JSON"]),
]


@pytest.mark.parametrize(("entry", "env", "args", "says"), [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_a_hostile_service_or_variable_is_one_named_error_within_seconds(tmp_path, monkeypatch, addresses, entry,
                                                                         env, args, says):
    keys = {**addresses, "tmp": str(tmp_path)}
    if any("{halfdb}" in v for v in env.values()):
        keys["halfdb"] = str(half_size_db(tmp_path / "mlflow.db"))
    if any("{deleteddb}" in v for v in env.values()):
        keys["deleteddb"] = str(deleted_experiment_db(tmp_path / "mlflow.db"))
    for name in ("MLFLOW_TRACKING_URI", "MLFLOW_REGISTRY_URI", "LFDT_MLFLOW_EXPERIMENT", "RAY_ADDRESS", "DVC_STAGE",
                 "DVC_ROOT", "LFDT_NUMERICS", *(k for k in os.environ if k.startswith("MLFLOW_HTTP_REQUEST"))):
        monkeypatch.delenv(name, raising=False)
    for name, value in env.items():
        monkeypatch.setenv(name, value.format(**keys))
    monkeypatch.chdir(tmp_path)  # an empty folder: nothing may be written before the error
    t0 = time.monotonic()
    code, stderr = _in_thread(lambda: entry(Ctx(tmp_path, addresses, [a.format(**keys) for a in args])))
    took = time.monotonic() - t0
    errors = [line for line in stderr.splitlines() if line.startswith("error: ")]
    assert code == 2, f"exit {code}:\n{stderr[-3000:]}"
    assert len(errors) == 1, stderr[-3000:]
    for part in says:
        assert part.format(**keys) in errors[0], errors[0]
    assert "Traceback" not in stderr, stderr[-3000:]
    assert took < LIMIT_S, f"took {took:.1f} s: {errors[0]}"
    assert not (tmp_path / "preflight.txt").exists(), "preflight said the checks passed"


def test_a_healthy_looking_service_passes_the_same_checks(tmp_path):
    """The checks refuse what is wrong only: a store that answers, a gRPC server, a name of 256 characters."""
    from lfdt import inputs

    db = tmp_path / "good.db"
    con = sqlite3.connect(db)
    con.execute("CREATE TABLE experiments (experiment_id INTEGER PRIMARY KEY, name VARCHAR(256))")
    con.commit()
    con.close()
    inputs.sqlite_answers(db, "a good store", thorough=True)
    (tmp_path / "empty.db").touch()  # what a store is before MLflow makes its tables
    inputs.sqlite_answers(tmp_path / "empty.db", "a new store", thorough=True)
    with _tcp(b"\x00\x00\x00\x04\x00\x00\x00\x00\x00") as grpc_like:  # an HTTP/2 server's first SETTINGS frame
        inputs.tcp_service(grpc_like, "a gRPC server", "grpc", 2)
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("LFDT_MLFLOW_EXPERIMENT", "e" * 256)
        assert inputs.env_text("LFDT_MLFLOW_EXPERIMENT", "lfdt", 256) == "e" * 256
        mp.setenv("LFDT_NUMERICS", " Native ")
        assert inputs.env_choice("LFDT_NUMERICS", ("pinned", "native"), "pinned") == "native"
        mp.setenv("LFDT_NUMERICS", "")
        assert inputs.env_choice("LFDT_NUMERICS", ("pinned", "native"), "pinned") == "pinned"


def _raise(exc: BaseException) -> Callable[..., None]:
    def fail(*args, **kwargs) -> None:
        raise exc
    return fail


COMMANDS = {  # a command line, the function its work is in, what to patch it in, its arguments
    "sweep": ("lfdt.sweep.__main__", "run_sweep", []),
    "restore": ("lfdt.restore", "restore", []),
    "views": ("lfdt.mlflow_views", "install", []),
}


@pytest.mark.parametrize("fault", ["ctrl-c", "disk-full"])
@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_ctrl_c_or_a_full_disk_in_a_command_is_one_line(tmp_path, monkeypatch, command, fault):
    """The commands besides the stages (sweep, restore, the MLflow views): Ctrl-C is one line saying what is left
    and how to go on, exit 130; an OSError one line naming the file and the OS's reason, exit 2; no traceback."""
    import importlib

    module, function, args = COMMANDS[command]
    mod = importlib.import_module(module)
    exc = KeyboardInterrupt() if fault == "ctrl-c" else \
        OSError(28, "No space left on device", str(tmp_path / "out.json"))
    monkeypatch.setattr(mod, function, _raise(exc))
    monkeypatch.chdir(tmp_path)
    code, stderr = _in_thread(lambda: mod.main(args))
    errors = [line for line in stderr.splitlines() if line.startswith("error: ")]
    assert "Traceback" not in stderr and len(errors) == 1 and stderr.count("\n") == 1, stderr[-3000:]
    if fault == "ctrl-c":
        assert code == 130 and errors[0].startswith("error: interrupted (Ctrl-C): "), stderr
    else:
        assert code == 2 and errors[0] == f"error: {tmp_path / 'out.json'}: No space left on device", stderr


def test_a_ui_port_freed_a_moment_ago_counts_as_free():
    """`make mlflow-ui` right after the last one stopped: that server's closed connections (TIME_WAIT) do not hold
    its port, for the UI's server nor for the check before it; a listening server does."""
    from lfdt.errors import InputError
    from lfdt.mlflow_views import port_free

    port = services.free_port()
    server = socket.create_server(("127.0.0.1", port))
    client = socket.create_connection(("127.0.0.1", port))
    conn, _ = server.accept()
    with pytest.raises(InputError, match=f"127.0.0.1:{port} is in use"):
        port_free(f"http://127.0.0.1:{port}")
    conn.close()  # the server's side closes first: its end of the connection waits in TIME_WAIT on the port
    server.close()
    client.close()
    port_free(f"http://127.0.0.1:{port}")
