"""The deploy log: one CSV per task and method (``trial,success``), appended by ``python -m lfdt.robot deploy``
one trial at a time and read by the ``twin_evaluate`` stage (backend 'real'). One writer, one reader, one format.
"""

from __future__ import annotations

import csv
from pathlib import Path

from lfdt.csvlog import CsvLogError, append_rows

HEADER = ["trial", "success"]
OUTCOMES = {"True": True, "False": False}
"""How an outcome is written, and the only values the reader accepts."""


class DeployLogError(ValueError):
    """A deploy log that cannot be read as one: names the file and the row."""


def read_trials(path: str | Path) -> list[tuple[int, bool]]:
    """Every logged trial as (trial number, success), checked: the header, the outcomes, trial numbers 0, 1, 2, ...
    without gaps or repeats (the writer appends them in that order)."""
    path = Path(path)
    if not path.exists() or path.stat().st_size == 0:
        return []
    out = []
    with open(path, newline="") as fh:
        reader = csv.reader(fh)
        header = next(reader, None)
        if header != HEADER:
            raise DeployLogError(f"{path}: header {header} is not {HEADER}")
        for line, row in enumerate(reader, start=2):
            if not row:
                continue
            if len(row) != 2 or row[1] not in OUTCOMES:
                raise DeployLogError(f"{path}, line {line}: {row} is not a trial number and one of {list(OUTCOMES)}")
            try:
                trial = int(row[0])
            except ValueError:
                raise DeployLogError(f"{path}, line {line}: trial {row[0]!r} is not a number") from None
            if trial != len(out):
                raise DeployLogError(f"{path}, line {line}: trial {trial} where trial {len(out)} was expected "
                                     "(a repeated, missing or reordered trial)")
            out.append((trial, OUTCOMES[row[1]]))
    return out


def append_trial(path: str | Path, trial: int, success: bool) -> None:
    """Append one trial's outcome, durably (it survives a crash during the next trial), on a line of its own even
    when the file was edited by hand (:func:`lfdt.csvlog.append_rows`); a file with another header raises
    :class:`DeployLogError` naming it."""
    try:
        append_rows(path, HEADER, [[str(trial), "True" if success else "False"]])
    except CsvLogError as err:
        raise DeployLogError(str(err)) from None
