"""The deploy log: one CSV per task and method (``trial,success``), appended by ``python -m lfdt.robot deploy``
one trial at a time and read by the ``twin_evaluate`` stage (backend 'real'). One writer, one reader, one format.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

from lfdt import inputs
from lfdt.csvlog import CsvLogError, append_rows
from lfdt.csvlog import check_appendable as check_appendable_csv
from lfdt.errors import InputError

HEADER = ["trial", "success"]
OUTCOMES = {"True": True, "False": False}
"""How an outcome is written, and the only values the reader accepts."""


EXPECTED = "a deploy log (CSV 'trial,success', one row per trial, as `python -m lfdt.robot deploy` writes it)"


class DeployLogError(InputError, ValueError):
    """A deploy log that cannot be read as one: names the file and the row (an InputError: the deploy command and
    the twin_evaluate stage end with its message and exit 2)."""


def read_trials(path: str | Path, what: str = "deploy log") -> list[tuple[int, bool]]:
    """Every logged trial as (trial number, success), checked: the header, the outcomes, trial numbers 0, 1, 2, ...
    without gaps or repeats (the writer appends them in that order)."""
    path = Path(path)
    if not path.exists():
        return []
    # a folder, a device or bytes that are not UTF-8 are named errors, not tracebacks
    text = inputs.read_text(path, what, EXPECTED, error=DeployLogError)
    if not text:
        return []
    out = []
    with io.StringIO(text, newline="") as fh:  # newline="": CRLF, LF and CR-only endings alike
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


def check_appendable(path: str | Path, what: str = "--log") -> int:
    """Before a trial runs: the log can take its outcome (a regular file that can be appended to, or created, on a
    disk that is not full) and what it holds is a deploy log; returns the number of trials logged. Raises
    DeployLogError naming the file."""
    try:
        check_appendable_csv(path, HEADER, what)
    except (CsvLogError, InputError) as err:
        raise DeployLogError(str(err)) from None
    return len(read_trials(path, what))


def append_trial(path: str | Path, trial: int, success: bool) -> None:
    """Append one trial's outcome, durably (it survives a crash during the next trial), on a line of its own even
    when the file was edited by hand (:func:`lfdt.csvlog.append_rows`); a file with another header raises
    :class:`DeployLogError` naming it."""
    try:
        append_rows(path, HEADER, [[str(trial), "True" if success else "False"]])
    except CsvLogError as err:
        raise DeployLogError(str(err)) from None
