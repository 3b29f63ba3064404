"""Jobs side by side in worker processes: results in job order, and no worker outlives a killed stage."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from lfdt import parallel

ROOT = Path(__file__).resolve().parents[1]
IMPORTED_BY = os.getpid()
"""The process that imported this module (a forkserver's worker that finds another did not import it itself)."""


def square(job: int, progress) -> int:
    progress.update(1)
    return job * job


def fail_on_two(job: int, progress) -> int:
    if job == 2:
        raise ValueError("two is bad")
    return job


def test_results_come_back_in_job_order():
    assert parallel.run_jobs(square, [3, 1, 2], workers=2, total=3) == [9, 1, 4]
    assert parallel.run_jobs(square, [3, 1, 2], workers=1, total=3) == [9, 1, 4]
    assert parallel.run_jobs(square, [3, 1, 2], workers=2, total=3, method="spawn") == [9, 1, 4]


def test_the_workers_start_from_a_forkserver_unless_told(monkeypatch):
    import pytest

    monkeypatch.delenv(parallel.START_METHOD_VAR, raising=False)
    assert parallel.start_method() == "forkserver"
    monkeypatch.setenv(parallel.START_METHOD_VAR, "spawn")
    assert parallel.start_method() == "spawn"
    monkeypatch.setenv(parallel.START_METHOD_VAR, "fork")
    with pytest.raises(parallel.StageError, match="LFDT_WORKER_START='fork': expected one of forkserver, spawn"):
        parallel.start_method()


def test_a_failing_job_stops_the_stage_named():
    import pytest

    with pytest.raises(RuntimeError, match=r"job 2 of 3 \(2\) failed: ValueError: two is bad"):
        parallel.run_jobs(fail_on_two, [1, 2, 3], workers=2)


STAGE = """
import sys, time
sys.path.insert(0, {tests!r})
from lfdt import parallel
import test_parallel
parallel.run_jobs(test_parallel.sleep_and_write, [({out!r}, 0), ({out!r}, 1)], workers=2)
"""


def sleep_and_write(job: tuple[str, int], progress) -> None:
    """A job that says it started (its pid), then would write its output 60 s later."""
    out, i = job
    Path(out, f"pid{i}").write_text(str(os.getpid()))
    time.sleep(60)
    Path(out, f"done{i}").write_text("written by an orphan")


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # a zombie (exited, not yet reaped by init) counts as gone
    stat = Path(f"/proc/{pid}/stat")
    return stat.exists() and stat.read_text().split(")")[-1].split()[0] != "Z"


def test_workers_end_when_the_stage_process_is_killed(tmp_path):
    stage = subprocess.Popen([sys.executable, "-c", STAGE.format(tests=str(ROOT / "tests"), out=str(tmp_path))],
                             cwd=ROOT)
    try:
        deadline = time.monotonic() + 60
        while len(list(tmp_path.glob("pid*"))) < 2:
            assert stage.poll() is None and time.monotonic() < deadline, "the jobs did not start"
            time.sleep(0.1)
        pids = [int(p.read_text()) for p in tmp_path.glob("pid*")]
        stage.send_signal(signal.SIGKILL)  # as a machine's OOM killer or `kill -9` would
        stage.wait(10)
        deadline = time.monotonic() + 10
        while any(_alive(p) for p in pids) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not any(_alive(p) for p in pids), "a worker outlived its stage"
        assert not list(tmp_path.glob("done*"))
    finally:
        stage.kill()
        for p in tmp_path.glob("pid*"):
            try:
                os.kill(int(p.read_text()), signal.SIGKILL)
            except ProcessLookupError:
                pass


WHERE = """
import json, sys
sys.path.insert(0, {tests!r})
from lfdt import parallel
import test_parallel
print(json.dumps(parallel.run_jobs(test_parallel.where_imported, [0, 1], workers=2)))
"""


def where_imported(job: int, progress) -> dict:
    """Which process imported the job's module, this worker's pid and parent's, and what MLflow it finds loaded."""
    return {"imported_by": IMPORTED_BY, "pid": os.getpid(), "ppid": os.getppid(),
            "modules": [m for m in ("mlflow", "mlflow.store.tracking.sqlalchemy_store") if m in sys.modules]}


def test_the_forkserver_imports_the_jobs_module_and_mlflow_once_for_its_workers(tmp_path):
    """The workers are forks of a server that imported the job's module and what its MLflow run imports (for the
    default sqlite store, the SQL store too): neither worker imports them again (Python 3.11's forkserver preloads
    nothing unless told)."""
    from lfdt import mlflow_runs

    env = {k: v for k, v in os.environ.items() if k not in ("MLFLOW_TRACKING_URI", parallel.START_METHOD_VAR)}
    # on PYTHONPATH, as lfdt is installed: Python 3.11's server ignores the parent's sys.path (CPython gh-117378)
    env["PYTHONPATH"] = str(ROOT / "tests")
    out = subprocess.run([sys.executable, "-c", WHERE.format(tests=str(ROOT / "tests"))], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-3000:]
    workers = json.loads(out.stdout.splitlines()[-1])
    assert len(workers) == 2
    for w in workers:  # one worker may have run both jobs
        assert w["imported_by"] == w["ppid"] != w["pid"], w  # the server imported it before the fork
        assert w["modules"] == ["mlflow", "mlflow.store.tracking.sqlalchemy_store"], w
    assert mlflow_runs.worker_modules("http://127.0.0.1:5000") == ("mlflow",)
    assert mlflow_runs.worker_modules("postgresql+psycopg2://u@h/db")[1] == "mlflow.store.tracking.sqlalchemy_store"


CTRL_C = """
import sys
sys.path.insert(0, {tests!r})
from lfdt import parallel, stage
import test_parallel
stage.main(lambda: parallel.run_jobs(test_parallel.square, [1, 2], workers=2, preload=["slow_preload"]))
"""


def test_ctrl_c_while_the_forkserver_imports_is_the_stages_one_line(tmp_path):
    """Ctrl-C (SIGINT to the whole process group, as a terminal sends it) while the workers' server is still
    importing its modules: the stage's one line and exit 130, no traceback from the server (Python 3.11's server
    imports before it ignores SIGINT), and no process of the stage left behind."""
    env = {k: v for k, v in os.environ.items() if k not in ("MLFLOW_TRACKING_URI", parallel.START_METHOD_VAR)}
    env["PYTHONPATH"] = str(ROOT / "tests")
    stage = subprocess.Popen([sys.executable, "-c", CTRL_C.format(tests=str(ROOT / "tests"))], cwd=tmp_path,
                             env=env, stderr=subprocess.PIPE, text=True, start_new_session=True,
                             preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        time.sleep(2)  # the server sleeps 4 s in slow_preload's import
        assert stage.poll() is None, stage.stderr.read()
        os.killpg(stage.pid, signal.SIGINT)
        _, err = stage.communicate(timeout=30)
        lines = [line for line in err.replace("\r", "\n").splitlines() if line.strip() and "it/s" not in line
                 and "s/it" not in line and not line.startswith("jobs:")]
        assert stage.returncode == 130, err[-3000:]
        assert lines == ["error: interrupted (Ctrl-C): the stage's outputs are incomplete; `dvc repro` reruns it"], \
            err[-3000:]
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            try:
                os.killpg(stage.pid, 0)
            except ProcessLookupError:
                break
            time.sleep(0.2)
        else:
            raise AssertionError("a process of the stage (its forkserver?) outlived the Ctrl-C")
    finally:
        try:
            os.killpg(stage.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


LIGHT_STAGES = ("train_translator", "track_demos", "train_bc", "twin_collect", "twin_train", "twin_evaluate")
"""Stages that name their job (parallel.Job) and need nothing else heavy: their own process imports no torch,
MuJoCo or MLflow store before its workers start (about 2.5 s of a small stage's start on a 2-core EPYC)."""


def test_a_stage_that_names_its_job_starts_without_torch():
    probe = ("import importlib, json, sys; sys.path.insert(0, 'stages'); importlib.import_module(sys.argv[1]); "
             "print(json.dumps([m for m in ('torch', 'mujoco', 'mlflow', 'stable_baselines3') if m in sys.modules]))")
    for name in LIGHT_STAGES:
        out = subprocess.run([sys.executable, "-c", probe, name], cwd=ROOT, capture_output=True, text=True,
                             timeout=60)
        assert out.returncode == 0, out.stderr[-2000:]
        assert json.loads(out.stdout) == [], f"stages/{name}.py imports {out.stdout.strip()} before its workers start"


def fail_at_once_or_sleep(job: tuple[str, int], progress) -> int:
    """Job 0 fails at once; job 1 says it started (its pid), then would run 60 s and write that it finished."""
    out, i = job
    if i == 0:
        deadline = time.monotonic() + 30
        while not Path(out, "pid1").exists() and time.monotonic() < deadline:  # the other job has started
            time.sleep(0.05)
        raise ValueError("zero is bad")
    Path(out, "pid1").write_text(str(os.getpid()))
    time.sleep(60)
    Path(out, "done1").write_text("finished in vain")
    return i


def test_a_failing_job_stops_the_others_at_once(tmp_path):
    """The stage reports a failed job without waiting for the others to finish theirs (they could train for
    minutes), and ends their workers."""
    import pytest

    t0 = time.monotonic()
    with pytest.raises(RuntimeError, match=r"job 1 of 2 .* failed: ValueError: zero is bad"):
        parallel.run_jobs(fail_at_once_or_sleep, [(str(tmp_path), 0), (str(tmp_path), 1)], workers=2)
    assert time.monotonic() - t0 < 30, "the stage waited for the other job"
    pid = int((tmp_path / "pid1").read_text())
    deadline = time.monotonic() + 10
    while _alive(pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _alive(pid) and not (tmp_path / "done1").exists()
