"""Hostile input to the stages: a damaged data file, model or tracking store ends the stage with exit code 2 and one
line that names the file, column or URI and what was expected, before any output is written; so does a full disk
(naming the file), and Ctrl-C is one line too (exit code 130). Each case copies what it damages from the smoke
project's outputs into its own folder and runs the stage's script in this process (no interpreter to start per case);
a new case is one row of :data:`CASES`.
"""

from __future__ import annotations

import errno
import os
import runpy
import shutil
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import smoke

pytestmark = pytest.mark.xdist_group("smoke_project")  # reads the smoke project's outputs: built once, on that worker


def _rewrite(src: Path, dst: Path, change: Callable[[pa.Table], pa.Table]) -> None:
    """``src`` changed by ``change`` into ``dst``, with the file's and the columns' metadata kept."""
    table = pq.read_table(src)
    pq.write_table(change(table).replace_schema_metadata(table.schema.metadata), dst)


def _nan_at(column: str, row: int) -> Callable[[pa.Table], pa.Table]:
    def change(t: pa.Table) -> pa.Table:
        i = t.column_names.index(column)
        values = t.column(i).to_numpy().copy()
        values[row] = np.nan
        return t.set_column(i, t.schema.field(i), pa.array(values, type=t.schema.field(i).type))
    return change


@dataclass
class Case:
    """One hostile input: which stage, how its input is made from the smoke project's, what the line must say."""

    script: str
    prepare: Callable[[Path, Path], list[str]]
    """(smoke project, this case's folder) -> the stage's arguments, after damaging a copy of its input there."""
    says: str
    """What the one error line must contain (``{case}`` stands for this case's folder)."""
    env: dict[str, str] = field(default_factory=dict)
    fault: Callable[[pytest.MonkeyPatch], None] | None = None
    """What goes wrong around the stage while it runs (a full disk, Ctrl-C), patched in for the case."""
    code: int = 2
    """The stage's exit code."""


def _random(root: Path, tmp: Path, change=None) -> list[str]:
    shutil.copytree(root / "data/random", tmp / "random")
    if change:
        _rewrite(root / "data/random/Y.parquet", tmp / "random/Y.parquet", change)
    return ["--random-dir", str(tmp / "random"), "--out-dir", str(tmp / "out"), "--report",
            str(tmp / "reports/dynamics.json"), "--curve", str(tmp / "reports/curve.csv")]


def _demos(root: Path, tmp: Path, change=None, twin: bool = False, missing: str | None = None) -> list[str]:
    (tmp / "demos").mkdir()
    for pairing in ("R1H", "HR2"):
        src = root / "data/demos" / f"{pairing}.parquet"
        if pairing == missing:
            continue
        if twin:  # a twin recording (a folder of episodes of another task) given as the box push's demonstrations
            shutil.copytree(root / "data/twin/peg_insertion/s0" / f"demos_{pairing}", tmp / "demos" / src.name)
        elif change and pairing == "R1H":
            _rewrite(src, tmp / "demos" / src.name, change)
        else:
            shutil.copy(src, tmp / "demos" / src.name)
    return ["--demos", "3", "--demos-dir", str(tmp / "demos"), "--bc-data", str(tmp / "out")]


def _policies(root: Path, tmp: Path, damage: Callable[[Path], None]) -> list[str]:
    shutil.copytree(root / "models/bc/lfdt-d3", tmp / "policies/lfdt-d3")
    damage(tmp / "policies/lfdt-d3/s0/pi.pt")
    return ["--method", "lfdt", "--demos", "3", "--policies", str(tmp / "policies"), "--videos", str(tmp / "out"),
            "--reports", str(tmp / "reports")]


def _truncate(pt: Path) -> None:
    pt.write_bytes(pt.read_bytes()[:200])


def _store(root: Path, tmp: Path) -> list[str]:
    return ["--domain", "Y", "--out-dir", str(tmp / "out"), "--reports", str(tmp / "reports")]


CORRUPT_DB = "corrupt.db"


def _raise(exc: BaseException) -> Callable[..., None]:
    def fail(*args, **kwargs) -> None:
        raise exc
    return fail


def _full_disk(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every Parquet write fails as on a full disk: the OS's error names no file."""
    monkeypatch.setattr(pq, "write_table", _raise(OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))))


def _ctrl_c(monkeypatch: pytest.MonkeyPatch) -> None:
    """Ctrl-C while the stage draws its demonstration subsets."""
    from lfdt import data

    monkeypatch.setattr(data, "demo_subset", _raise(KeyboardInterrupt()))

CASES = {
    "dynamics-zero-rows": Case("stages/fit_dynamics.py", lambda r, t: _random(r, t, lambda tb: tb.slice(0, 0)),
                               "{case}/random/Y.parquet: holds no transitions (0 rows)"),
    "dynamics-missing-column": Case("stages/fit_dynamics.py",
                                    lambda r, t: _random(r, t, lambda tb: tb.drop(["state.r1.q0"])),
                                    "{case}/random/Y.parquet: missing columns ['state.r1.q0']"),
    "dynamics-nan-state": Case("stages/fit_dynamics.py", lambda r, t: _random(r, t, _nan_at("next_state.box.x", 7)),
                               "{case}/random/Y.parquet: column next_state.box.x is nan at row 7"),
    "demos-nan-action": Case("stages/select_demos.py", lambda r, t: _demos(r, t, _nan_at("action.r1.tau0", 5)),
                             "{case}/demos/R1H.parquet: column action.r1.tau0 is nan at row 5"),
    "demos-from-the-twin": Case("stages/select_demos.py", lambda r, t: _demos(r, t, twin=True),
                                "{case}/demos/R1H.parquet holds demos data of domain R1H (task 'peg_insertion' "
                                "where 'box_push' is needed)"),
    "demos-pairing-missing": Case("stages/select_demos.py", lambda r, t: _demos(r, t, missing="HR2"),
                                  "{case}/demos/HR2.parquet is missing"),
    "full-disk": Case("stages/select_demos.py", _demos, "raw_R1H.parquet: cannot write it: No space left on device",
                      fault=_full_disk),
    "ctrl-c": Case("stages/select_demos.py", _demos, "interrupted (Ctrl-C)", fault=_ctrl_c, code=130),
    "policy-truncated": Case("stages/evaluate.py", lambda r, t: _policies(r, t, _truncate),
                             "{case}/policies/lfdt-d3/s0/pi.pt is not a saved state dict"),
    "policy-of-another-model": Case("stages/evaluate.py",
                                    lambda r, t: _policies(r, t, lambda pt: shutil.copy(
                                        r / "models/dynamics/dynamics.pt", pt)),
                                    "{case}/policies/lfdt-d3/s0/pi.pt holds the weights of another model than a "
                                    "BCMember"),
    "policy-without-its-config": Case("stages/evaluate.py",
                                      lambda r, t: _policies(r, t, lambda pt: pt.with_suffix(".json").unlink()),
                                      "{case}/policies/lfdt-d3/s0/pi.json is missing"),
    "store-ftp": Case("stages/collect_random.py", _store, "MLFLOW_TRACKING_URI=ftp://example.org/x: scheme 'ftp' "
                      "is not a tracking store", {"MLFLOW_TRACKING_URI": "ftp://example.org/x"}),
    "store-unknown-scheme": Case("stages/collect_random.py", _store, "scheme 'nonsense' is not a tracking store",
                                 {"MLFLOW_TRACKING_URI": "nonsense://x"}),
    "store-file": Case("stages/collect_random.py", _store, "a file store is not a tracking store",
                       {"MLFLOW_TRACKING_URI": "file:///proc/mlruns"}),
    "store-no-driver": Case("stages/collect_random.py", _store, "its database driver cannot be loaded",
                            {"MLFLOW_TRACKING_URI": "postgresql+pg8000://lfdt:secret@127.0.0.1:5/mlflow"}),
    "store-sqlite-folder": Case("stages/collect_random.py", _store, "{case} is a folder; name the database file",
                                {"MLFLOW_TRACKING_URI": "sqlite:///{case}"}),
    "store-sqlite-query": Case("stages/collect_random.py", _store, "a query string is not supported",
                               {"MLFLOW_TRACKING_URI": "sqlite:////tmp/mlflow.db?mode=ro"}),
    "store-corrupt-sqlite": Case("stages/collect_random.py", _store, f"{{case}}/{CORRUPT_DB} is not an SQLite "
                                 "database", {"MLFLOW_TRACKING_URI": f"sqlite:///{{case}}/{CORRUPT_DB}"}),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_a_damaged_input_is_one_named_error_before_any_output(name, smoke_project, tmp_path, monkeypatch, capsys):
    case = CASES[name]
    root = smoke_project.root
    (tmp_path / CORRUPT_DB).write_bytes(b"not a database\n" * 64)
    args = case.prepare(root, tmp_path)
    params = tmp_path / "params.yaml"
    params.write_text(smoke.smoke_params_yaml({"grid": {"workers": 1}}))  # jobs in this process: nothing to spawn
    for key, value in case.env.items():
        monkeypatch.setenv(key, value.format(case=tmp_path))
    monkeypatch.chdir(root)  # the stages find their workspace (and its tracking store) from here
    monkeypatch.setattr(sys, "argv", [case.script, *args, "--params", str(params)])
    if case.fault is not None:
        case.fault(monkeypatch)
    with pytest.raises(SystemExit) as exit_:
        runpy.run_path(str(root / case.script), run_name="__main__")
    err = capsys.readouterr().err
    errors = [line for line in err.splitlines() if line.startswith("error: ")]
    assert exit_.value.code == case.code, err[-3000:]
    assert len(errors) == 1 and "Traceback" not in err, err[-3000:]
    assert case.says.format(case=tmp_path) in errors[0], errors[0]
    assert "secret" not in err
    written = [p for p in (tmp_path / "out", tmp_path / "reports")
               if p.exists() and any(f.is_file() for f in p.rglob("*"))]  # an empty folder is no output
    assert not written, f"the stage wrote {written} before failing"
