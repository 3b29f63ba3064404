"""A stage never outlives the `dvc repro` that started it: killed with SIGKILL mid-stage, the stage and its workers
end within seconds, the rerun's output is an uninterrupted run's, and MLflow holds no run left RUNNING. Two copies of
one stage never run at once. A tiny DVC project whose stage has two workers that log to MLflow stands in for a
training stage (the same :func:`lfdt.stage.main`, :func:`lfdt.parallel.run_jobs` and MLflow runs)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import mlflow
import pytest

from lfdt import lifeline
from lfdt.errors import StageError

JOBS = '''
"""Two jobs that log to MLflow and take their time (a stand-in for training)."""
import os, time
from pathlib import Path
from lfdt import mlflow_runs


def job(seed, progress=None):
    with mlflow_runs.stage_run("tiny", {"seed": seed}, run_name=f"tiny s{seed}") as run:
        Path(os.environ["TINY_STARTED"], f"s{seed}").touch()
        time.sleep(float(os.environ.get("TINY_SLEEP", "0")))
        run.metrics({"value": seed * 2.0})
    return {"seed": seed, "value": seed * 2}
'''

STAGE = '''
import json, sys
from pathlib import Path
from lfdt import parallel, stage
import tiny_jobs


def run():
    out = Path(sys.argv[1])
    results = parallel.run_jobs(tiny_jobs.job, [0, 1], workers=2, desc="tiny")
    out.write_text(json.dumps(results))


if __name__ == "__main__":
    stage.main(run)
'''


def _project(root: Path) -> Path:
    root.mkdir()
    (root / "tiny_jobs.py").write_text(textwrap.dedent(JOBS))
    (root / "tiny_stage.py").write_text(textwrap.dedent(STAGE))
    (root / "dvc.yaml").write_text("stages:\n  tiny:\n    cmd: python tiny_stage.py out.json\n"
                                   "    deps: [tiny_stage.py, tiny_jobs.py]\n    outs: [out.json]\n")
    subprocess.run(["git", "init", "-q"], cwd=root, check=True)
    subprocess.run([sys.executable, "-m", "dvc", "init", "-q"], cwd=root, check=True)
    return root


def _env(root: Path, sleep: float) -> dict[str, str]:
    started = root / "started"
    started.mkdir(exist_ok=True)
    return {**os.environ, "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}", "DVC_NO_ANALYTICS": "1",
            "PYTHONPATH": os.pathsep.join([str(root), *filter(None, [os.environ.get("PYTHONPATH")])]),
            "MLFLOW_TRACKING_URI": f"sqlite:///{root / 'mlflow.db'}",
            "TINY_STARTED": str(started), "TINY_SLEEP": str(sleep)}


def _processes_of(root: Path) -> list[int]:
    """Processes whose command line or working directory is in the project (the stage, its workers)."""
    out = []
    for pid in (int(p) for p in os.listdir("/proc") if p.isdigit()):
        try:
            cwd = os.readlink(f"/proc/{pid}/cwd")
            with open(f"/proc/{pid}/cmdline", "rb") as fh:
                cmd = fh.read().decode(errors="replace")
        except OSError:
            continue
        if pid != os.getpid() and (cwd.startswith(str(root)) or str(root) in cmd):
            out.append(pid)
    return out


@pytest.mark.parametrize("reaped", [True, False], ids=["reaped", "zombie"])
def test_a_killed_repro_takes_its_stage_and_workers_down(tmp_path, reaped):
    """``reaped``: the killed `dvc repro` is waited for at once (a shell's job); else it stays a zombie while its
    stage still holds its output pipe, as under a program that reads that pipe to its end (the sweep's chains)."""
    root = _project(tmp_path / "p")
    env = _env(root, sleep=120)
    repro = subprocess.Popen([sys.executable, "-m", "dvc", "repro"], cwd=root, env=env, stdout=subprocess.PIPE,
                             stderr=subprocess.STDOUT, start_new_session=True)
    try:
        deadline = time.time() + 120
        while len(list((root / "started").iterdir())) < 2:  # both workers are inside their MLflow runs
            assert repro.poll() is None and time.time() < deadline, repro.stdout.read().decode()[-3000:]
            time.sleep(0.1)
        assert len(_processes_of(root)) >= 4  # dvc, the stage, two workers (and a shell, a resource tracker)
        repro.kill()  # SIGKILL to `dvc repro` alone, not its group: nothing else is told
        if reaped:
            repro.wait()
        deadline = time.time() + 10
        while _processes_of(root) and time.time() < deadline:
            time.sleep(0.2)
        left = _processes_of(root)
        assert not left, f"processes left after `dvc repro` was killed: {left}"
    finally:
        for pid in _processes_of(root):
            os.kill(pid, signal.SIGKILL)
        repro.wait()

    # the orphans marked their own runs KILLED before they went (not the rerun's clean-up of stray runs)
    client = mlflow.MlflowClient(env["MLFLOW_TRACKING_URI"])
    exp = client.get_experiment_by_name("lfdt").experiment_id
    killed = sorted((r.info.run_name, r.info.status) for r in client.search_runs([exp]))
    assert killed == [("tiny s0", "KILLED"), ("tiny s1", "KILLED")], killed

    # the rerun runs the stage again, whole, and gives an uninterrupted run's output
    env = _env(root, sleep=0)
    for d in (root / "started",):
        for f in d.iterdir():
            f.unlink()
    done = subprocess.run([sys.executable, "-m", "dvc", "repro"], cwd=root, env=env, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    assert json.loads((root / "out.json").read_text()) == [{"seed": 0, "value": 0}, {"seed": 1, "value": 2}]

    runs = client.search_runs([exp])
    status = sorted((r.info.run_name, r.info.status) for r in runs)
    assert status == [("tiny s0", "FINISHED"), ("tiny s0", "KILLED"), ("tiny s1", "FINISHED"),
                      ("tiny s1", "KILLED")], status


def test_a_second_copy_of_a_stage_waits_then_names_the_first(tmp_path):
    holder = subprocess.Popen([sys.executable, "-c", textwrap.dedent(f"""
        import time
        from pathlib import Path
        from lfdt import lifeline
        with lifeline.stage_lock("python stages/x.py", Path({str(tmp_path)!r})):
            print("locked", flush=True)
            time.sleep(60)
        """)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        t0 = time.monotonic()
        with pytest.raises(StageError, match=f"already running \\(pid {holder.pid}, lock .*\\): `python stages/x.py`"):
            with lifeline.stage_lock("python stages/x.py", tmp_path, wait_s=1.0):
                pass
        assert time.monotonic() - t0 >= 1.0  # it waited for the first copy to end before refusing
        with lifeline.stage_lock("python stages/other.py", tmp_path, wait_s=1.0):  # another stage: no wait
            pass
    finally:
        holder.kill()
        holder.wait()
    with lifeline.stage_lock("python stages/x.py", tmp_path, wait_s=5.0):  # free again once the holder is gone
        pass


def test_a_process_dvc_did_not_start_watches_nothing(monkeypatch):
    monkeypatch.delenv(lifeline.DVC_STAGE_ENV, raising=False)
    assert lifeline.launcher() is None  # by hand, or in-process in a test: it lives as its user says
    assert lifeline.watch() is None


@pytest.mark.parametrize(("chain", "watched"), [
    ([(40, ["/bin/sh", "-c", "python stages/x.py"]), (30, ["/venv/bin/python", "/venv/bin/dvc", "repro"]),
      (20, ["-bash"]), (1, ["/sbin/init"])], 30),                          # dvc's script, through a shell
    ([(30, ["python3", "-m", "dvc", "exp", "run"]), (1, ["/sbin/init"])], 30),  # python -m dvc, no shell
    ([(40, ["/bin/sh", "-c", "python stages/x.py"]), (1, ["/sbin/init"])], lifeline.ORPHANED),  # dvc died: init
    ([(1, ["/sbin/init"])], lifeline.ORPHANED),                            # and the shell had exec'd the stage
    ([(40, ["/bin/sh", "-c", "x"]), (30, ["python", "notebook.py"]), (1, ["/sbin/init"])], 99),  # DVC's Python API
], ids=["dvc-script", "python-m-dvc", "dvc-gone", "dvc-gone-no-shell", "python-api"])
def test_the_watched_launcher_is_the_nearest_dvc_else_orphaned_else_the_parent(chain, watched):
    assert lifeline.launcher_in(chain, parent=99) == watched


def test_a_worker_whose_stage_is_gone_ends_at_once(tmp_path):
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    out = subprocess.run([sys.executable, "-c", f"from lfdt import lifeline; lifeline.watch({gone.pid}); "
                          "import time; time.sleep(30)"], timeout=60)
    assert out.returncode == lifeline.ORPHANED_EXIT
