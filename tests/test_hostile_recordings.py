"""Hostile recordings of the robots (issue 38): what a user's copying, renaming and merging can make of the folders
``python -m lfdt.robot record-random`` / ``record-demos`` write (``twin.real_dir/<task>/<name>/episode_*.parquet``).
With ``twin.backend: real`` the preflight stage reads them before `dvc repro` runs anything else: each case ends in
exit code 2 and one line ``error: ...`` naming the user's episode file (not twin_collect's copy of it) and what is
wrong, and preflight does not say the checks passed. Before, a file of another task in a folder was read with it, two
files holding the same episode were read as one episode, and a file of another domain or kind gave a line that went
on for the whole of its schema. A new case is one row of :data:`CASES`.
"""

from __future__ import annotations

import runpy
import shutil
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from lfdt import layout
from lfdt.config import TwinParams
from lfdt.data import DataFileError
from lfdt.rig.recording import EpisodeRecorder
from lfdt.tasks import registry
from lfdt.twin.collect import collect_seed
from lfdt.twin.common import RECORDING_NAMES, twin_schema

ROOT = Path(__file__).resolve().parents[1]
TASK = "block_push"


def _record(folder: Path, task: str, name: str, episodes: int = 2, steps: int = 3) -> None:
    """A recording as the robot CLI writes it (its recorder and schema), with made-up finite values."""
    kind, domain = name.split("_")
    tl = registry.get(task).layout
    n_state = len(tl.state_columns(domain))
    n_action = len(tl.action_columns(domain) if kind == "random" else tl.arm_action_columns(layout.robot_arm(domain)))
    rec = EpisodeRecorder(folder, twin_schema(task, domain, kind, {"seed": 0}), dt=0.1)
    rng = np.random.default_rng(0)
    for _ in range(episodes):
        rec.start()
        for _ in range(steps):
            rec.add(rng.uniform(-0.1, 0.1, n_state), rng.uniform(-0.01, 0.01, n_action),
                    rng.uniform(-0.1, 0.1, n_state))
        rec.finish()


def _recordings(real: Path) -> None:
    for name in RECORDING_NAMES:
        _record(real / TASK / name, TASK, name)


def _rewrite(f: Path, change: Callable[[pa.Table], pa.Table], keep_metadata: bool = True) -> None:
    t = pq.read_table(f)
    pq.write_table(change(t).replace_schema_metadata(t.schema.metadata if keep_metadata else None), f)


def _copy_in(src_name: str, dst_name: str, src_task: str = TASK) -> Callable[[Path], str]:
    """Episode 0 of another recording copied into ``dst_name`` under a new number (files moved by hand)."""
    def damage(real: Path) -> str:
        src = real / TASK / src_name / "episode_000000.parquet"
        if src_task != TASK:
            _record(real / src_task / src_name, src_task, src_name)
            src = real / src_task / src_name / "episode_000000.parquet"
        dst = real / TASK / dst_name / "episode_000999.parquet"
        shutil.copy(src, dst)
        return str(dst)
    return damage


def _merged(real: Path) -> str:
    """Two sessions' recordings merged: the second's episode 0 renamed to follow the first's files."""
    folder = real / TASK / "demos_R1H"
    shutil.copy(folder / "episode_000000.parquet", folder / "episode_000500.parquet")
    return str(folder / "episode_000500.parquet")


def _episode_file(name: str, write: Callable[[Path], None]) -> Callable[[Path], str]:
    def damage(real: Path) -> str:
        f = real / TASK / name / "episode_000001.parquet"
        write(f)
        return str(f)
    return damage


def _cut(f: Path) -> None:
    f.write_bytes(f.read_bytes()[:200])


def _folder(f: Path) -> None:
    f.unlink()
    f.mkdir()


def _loop(f: Path) -> None:
    f.unlink()
    f.symlink_to(f.name)


def _as_text(f: Path) -> None:
    _rewrite(f, lambda t: t.set_column(t.column_names.index("state.obj.x"), pa.field("state.obj.x", pa.string()),
                                       t.column("state.obj.x").cast(pa.string())))


def _without_metadata(f: Path) -> None:
    _rewrite(f, lambda t: t, keep_metadata=False)


def _nan(f: Path) -> None:
    def change(t: pa.Table) -> pa.Table:
        i = t.column_names.index("next_state.obj.yaw")
        v = t.column(i).to_numpy().copy()
        v[1] = np.nan
        return t.set_column(i, t.schema.field(i), pa.array(v, type=t.schema.field(i).type))
    _rewrite(f, change)


CASES: list[tuple[str, Callable[[Path], str], list[str]]] = [
    ("another-task", _copy_in("random_Y", "random_Y", src_task="peg_insertion"),
     ["{file} holds kind 'random', domain 'Y', task 'peg_insertion'", "task 'block_push'", "one recording"]),
    ("another-domain", _copy_in("random_R1H", "random_Y"), ["{file} holds kind 'random', domain 'R1H'"]),
    ("demos-among-random", _copy_in("demos_HR2", "random_HR2"), ["{file} holds kind 'demos', domain 'HR2'"]),
    ("merged-sessions", _merged, ["{file} and episode_000000.parquet beside it both hold episode 0"]),
    ("cut-short", _episode_file("random_Y", _cut), ["{file}: not a readable Parquet file"]),
    ("a-folder", _episode_file("random_Y", _folder), ["{file}: not a file (a folder)"]),
    ("a-link-to-itself", _episode_file("random_Y", _loop), ["{file}: not a file (a broken link)"]),
    ("text-column", _episode_file("random_Y", _as_text), ["{file}: its columns differ", "state.obj.x is string"]),
    ("no-metadata", _episode_file("demos_HR2", _without_metadata), ["{file} holds kind None"]),
    ("nan-state", _episode_file("random_R1H", _nan), ["random_R1H: column next_state.obj.yaw is nan"]),
]


def _preflight(tmp: Path, monkeypatch: pytest.MonkeyPatch) -> tuple[int, Path]:
    """Run the preflight stage in-process on params.yaml with backend 'real' and the box push only; its exit code and
    the file it writes when the checks pass."""
    monkeypatch.chdir(tmp)  # twin.real_dir (data/real) is relative
    monkeypatch.setenv("MLFLOW_TRACKING_URI", f"sqlite:///{tmp}/mlflow.db")
    params = tmp / "params.yaml"
    params.write_text((ROOT / "params.yaml").read_text().replace("backend: sim", "backend: real", 1)
                      .replace("tasks: [block_push, peg_insertion]", "tasks: [block_push]", 1))
    out = tmp / "preflight.txt"
    monkeypatch.setattr(sys, "argv", [str(ROOT / "stages/preflight.py"), "--params", str(params), "--out", str(out)])
    try:
        runpy.run_path(sys.argv[0], run_name="__main__")
    except SystemExit as stop:
        return int(stop.code or 0), out
    return 0, out


@pytest.mark.parametrize(("damage", "says"), [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_a_hostile_recording_stops_preflight_in_one_line_naming_the_users_file(tmp_path, monkeypatch, capsys,
                                                                              damage, says):
    real = tmp_path / "data" / "real"
    _recordings(real)
    file = damage(real)
    code, out = _preflight(tmp_path, monkeypatch)
    stderr = capsys.readouterr().err
    errors = [line for line in stderr.splitlines() if line.startswith("error: ")]
    assert code == 2, stderr[-3000:]
    assert len(errors) == 1 and len(stderr.strip().splitlines()) == 1, stderr[-3000:]
    for part in says:
        assert part.format(file=Path(file).relative_to(tmp_path)) in errors[0], errors[0]
    assert not out.exists(), "preflight said the checks passed"


def test_the_same_recordings_undamaged_pass(tmp_path, monkeypatch, capsys):
    """The checks refuse what is wrong only: the recordings as the CLI writes them pass preflight."""
    _recordings(tmp_path / "data" / "real")
    code, out = _preflight(tmp_path, monkeypatch)
    assert code == 0 and out.exists(), capsys.readouterr().err[-3000:]


def test_twin_collect_names_the_users_file_not_its_copy(tmp_path, monkeypatch):
    """twin_collect copies the recordings under the twin's data folder; a damaged one is named where the user keeps
    it, before anything is copied."""
    monkeypatch.chdir(tmp_path)
    _recordings(tmp_path / "data" / "real")
    file = _merged(tmp_path / "data" / "real")
    p = TwinParams.model_validate({**TwinParams().model_dump(), "backend": "real", "tasks": [TASK]})
    with pytest.raises(DataFileError) as err:
        collect_seed(TASK, p, 3, tmp_path / "twin")
    assert str(err.value).startswith(str(Path(file).relative_to(tmp_path))), err.value
    assert not (tmp_path / "twin" / TASK / "s3" / "demos_R1H").exists()
