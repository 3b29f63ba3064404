"""Hostile params files (issue 38): what a user's editor, a merge or a copy can make of params.yaml. The preflight
stage, which `dvc repro` runs before any other, reads each: it ends in exit code 2 and one line ``error: ...`` naming
the file and the line, key or folder, without a traceback and without saying the checks passed. A new case is one row
of :data:`CASES` (the repro table of tests/test_hostile_repro.py runs such cases through `dvc repro` itself).
"""

from __future__ import annotations

import runpy
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BASE = (ROOT / "params.yaml").read_text()


def _sub(old: str, new: str) -> Callable[[Path], Path]:
    """A params.yaml in ``tmp`` with the first ``old`` replaced by ``new``."""
    assert old in BASE, old

    def write(tmp: Path) -> Path:
        (tmp / "params.yaml").write_text(BASE.replace(old, new, 1))
        return tmp / "params.yaml"
    return write


def _bytes(data: bytes) -> Callable[[Path], Path]:
    def write(tmp: Path) -> Path:
        (tmp / "params.yaml").write_bytes(data)
        return tmp / "params.yaml"
    return write


def _folder(tmp: Path) -> Path:
    (tmp / "params.yaml").mkdir()
    return tmp / "params.yaml"


def _missing(tmp: Path) -> Path:
    return tmp / "params.yaml"


# (id, how the params file is made, what the one line must say); {file} is the params file's path
CASES = [
    ("not-utf8", _bytes(BASE.encode().replace(b"device: cpu", b"device: c\xffpu", 1)),
     ["params file {file}", "line 1", "byte 0xff", "not UTF-8"]),
    ("duplicate-key", _sub("device: cpu", "device: cpu\ndevice: cuda"),
     ["{file} is not valid YAML", "line 2", "the key 'device' a second time (first on line 1)"]),
    ("duplicate-nested-key", _sub("  iterations: 6000", "  iterations: 6000\n  iterations: 60"),
     ["{file} is not valid YAML", "the key 'iterations' a second time"]),
    ("unclosed-list", _sub("device: cpu", "device: [cpu"), ["{file} is not valid YAML", "line 3, column 1"]),
    ("tab-indent", _sub("  timestep: 0.005", "\ttimestep: 0.005"),
     ["{file} is not valid YAML", "line 4, column 1", "'\\t'"]),
    ("python-tag", _sub("device: cpu", "device: !!python/object/apply:os.system ['true']"),
     ["{file} is not valid YAML", "line 1, column 9", "python/object/apply"]),
    ("a-folder", _folder, ["params file {file}", "is a folder, not a file"]),
    ("missing", _missing, ["params file {file}", "no such file"]),
    ("not-a-mapping", _bytes(b"- device\n- cpu\n"), ["the top level must be a mapping, got list"]),
    ("nan", _sub("timestep: 0.005", "timestep: .nan"), ["env.timestep = nan", "finite"]),
    ("trials-past-the-start-states", _sub("  trials: 200  # Trials per", "  trials: 100001  # Trials per"),
     ["evaluation.trials = 100001", "<= 100000"]),
    ("random-episodes-past-the-start-states", _sub("transitions: 400000", "transitions: 20000000"),
     ["random: transitions = 20000000 in episodes of episode_steps = 100 are 200000 episodes",
      "a seed has 100000 start states"]),
    ("twin-demos-past-the-start-states", _sub("demos_per_pairing: 10", "demos_per_pairing: 6000"),
     ["twin: demos_per_pairing = 6000", "at most 5000"]),
    ("one-demo-with-a-holdout", _sub("demos: [50, 100, 200]", "demos: [1, 100, 200]"),
     ["grid.demos = 1 with translator.holdout_fraction = 0.1: 1 of 1 demonstrations per pairing would be held out"]),
    ("box-out-of-reach", _sub("    start: [0.0, 0.22]", "    start: [0.0, 0.36]"),
     ["params.yaml env: in domain", "out of reach at the start with the box at", "env.box.start"]),
    ("unknown-twin-task", _sub("tasks: [block_push, peg_insertion]", "tasks: [block_push, peg_insert]"),
     ["twin.tasks: unknown task(s) ['peg_insert']", "'peg_insertion'"]),
    ("unknown-twin-task-override", _sub("task_bc: {block_push: {input_noise: 0.1}}",
                                       "task_bc: {block_push: {input_noise: 0.1}, peg_insert: {input_noise: 0.1}}"),
     ["twin.task_bc: unknown task(s) ['peg_insert']"]),
    ("real-backend-no-recordings", _sub("backend: sim", "backend: real"),
     ["twin.backend is 'real'", "block_push/random_Y holds no recording", "record-random"]),
]


@pytest.mark.parametrize(("make", "says"), [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_a_hostile_params_file_stops_preflight_in_one_named_line(tmp_path, monkeypatch, capsys, make, says):
    monkeypatch.chdir(tmp_path)  # real_dir (data/real) is relative: an empty folder has no recordings
    monkeypatch.setenv("MLFLOW_TRACKING_URI", f"sqlite:///{tmp_path}/mlflow.db")
    path = make(tmp_path)
    out = tmp_path / "preflight.txt"
    monkeypatch.setattr(sys, "argv", [str(ROOT / "stages/preflight.py"), "--params", str(path), "--out", str(out)])
    with pytest.raises(SystemExit) as stop:
        runpy.run_path(sys.argv[0], run_name="__main__")
    stderr = capsys.readouterr().err
    errors = [line for line in stderr.splitlines() if line.startswith("error: ")]
    assert stop.value.code == 2, stderr[-3000:]
    assert len(errors) == 1 and len(stderr.strip().splitlines()) == 1, stderr[-3000:]
    for part in says:
        assert part.format(file=path) in errors[0], errors[0]
    assert not out.exists(), "preflight said the checks passed"


def test_the_repository_params_pass_the_same_checks(tmp_path, monkeypatch, capsys):
    """The checks refuse what is wrong only: the repository's own params.yaml passes."""
    monkeypatch.setenv("MLFLOW_TRACKING_URI", f"sqlite:///{tmp_path}/mlflow.db")
    out = tmp_path / "preflight.txt"
    monkeypatch.setattr(sys, "argv", [str(ROOT / "stages/preflight.py"), "--params", str(ROOT / "params.yaml"),
                                      "--out", str(out)])
    runpy.run_path(sys.argv[0], run_name="__main__")
    assert out.exists(), capsys.readouterr().err
