"""tools/suite_timeline.py on a two-test suite: every phase of every test is on the timeline, on its worker, with
its length; the slow test is listed by name; the machine's busy share is a fraction; pytest's exit code is the
tool's. The suite runs in a pytest of its own, with and without xdist workers."""

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SUITE = """
import time

def test_slow():
    time.sleep({slow})

def test_quick():
    assert {ok}
"""


def _tool():
    spec = importlib.util.spec_from_file_location("suite_timeline", ROOT / "tools" / "suite_timeline.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _run(tmp_path: Path, ok: bool, workers: int = 0) -> tuple[subprocess.CompletedProcess, Path]:
    suite = tmp_path / "test_two.py"
    suite.write_text(SUITE.format(slow=1.2, ok=ok))
    out = tmp_path / "timeline.json"
    proc = subprocess.run([sys.executable, str(ROOT / "tools/suite_timeline.py"), "--workers", str(workers), "--out",
                           str(out), "--", str(suite), "-p", "no:cacheprovider", "--rootdir", str(tmp_path)],
                          capture_output=True, text=True, timeout=120)
    return proc, out


def test_the_timeline_has_every_phase_and_names_the_slow_test(tmp_path, monkeypatch):
    tool = _tool()
    monkeypatch.setattr(tool, "LONG_S", 1.0)
    proc, out = _run(tmp_path, ok=True)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    raw = [json.loads(line) for line in out.with_suffix(".jsonl").read_text().splitlines()]
    assert sorted((r["test"].split("::")[1], r["phase"]) for r in raw) == sorted(
        (t, p) for t in ("test_slow", "test_quick") for p in ("setup", "call", "teardown"))
    assert {r["worker"] for r in raw} == {"main"}
    slow = next(r for r in raw if r["test"].endswith("test_slow") and r["phase"] == "call")
    assert 1.15 <= slow["t1"] - slow["t0"] < 10
    summary = tool.summarise(raw, [(slow["t1"], 0.25), (slow["t1"], 0.75)])
    (w,) = summary["workers"].values()
    assert [p["test"].split("::")[1] for p in w["long"]] == ["test_slow"] and w["phases"] == 6
    assert summary["machine_busy_share"] == 0.5
    saved = json.loads(out.read_text())
    assert saved["pytest_exit_code"] == 0 and 0.0 <= saved["machine_busy_share"] <= 1.0
    assert saved["pytest_workers"] == 0 and saved["cpu_model"]


def test_a_failing_suite_fails_the_tool_and_each_worker_reports_as_itself(tmp_path):
    proc, out = _run(tmp_path, ok=False, workers=2)
    assert proc.returncode == 1, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert json.loads(out.read_text())["pytest_exit_code"] == 1
    raw = [json.loads(line) for line in out.with_suffix(".jsonl").read_text().splitlines()]
    assert {r["worker"] for r in raw} <= {"gw0", "gw1"} and len(raw) == 6


def test_a_suite_shorter_than_a_sample_still_gets_its_busy_share():
    """The sampler records the last, shorter interval when it is stopped: a suite that starts after one sample and
    ends before the next (a loaded machine's slow start) still has a busy share (CI, 2026-12-08: it had none)."""
    import threading
    import time

    tool = _tool()
    busy, stop = [], threading.Event()
    sampler = threading.Thread(target=tool._sample, args=(busy, stop), daemon=True)
    sampler.start()
    time.sleep(0.2)
    stop.set()
    sampler.join(timeout=5)
    assert not sampler.is_alive() and len(busy) == 1 and 0.0 <= busy[0][1] <= 1.0
