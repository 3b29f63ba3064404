"""Hostile files for the append-only logs (the real robot's deploy log, :mod:`lfdt.csvlog`): a file saved by hand or
by a spreadsheet is appended to without losing or gluing a row; one that cannot be is refused, naming the file or
the line, and left as it was. A new case is one row of a table."""

from __future__ import annotations

import pytest

from lfdt import csvlog
from lfdt.rig.deploy_log import DeployLogError, append_trial, read_trials

APPENDABLE = [
    # (id, the file before, the trials read after appending the next one, which succeeds)
    ("missing", None, [(0, True)]),
    ("empty", b"", [(0, True)]),
    ("header-only-no-newline", b"trial,success", [(0, True)]),
    ("lf", b"trial,success\n0,False\n", [(0, False), (1, True)]),
    ("crlf", b"trial,success\r\n0,False\r\n", [(0, False), (1, True)]),
    ("lf-no-final-newline", b"trial,success\n0,False\n1,False", [(0, False), (1, False), (2, True)]),
    ("crlf-no-final-newline", b"trial,success\r\n0,False\r\n1,False", [(0, False), (1, False), (2, True)]),
    ("blank-line-at-end", b"trial,success\n0,False\n\n", [(0, False), (1, True)]),
    ("cr-only", b"trial,success\r0,False\r", [(0, False), (1, True)]),  # old Mac tools
    ("cr-only-no-final-newline", b"trial,success\r0,False", [(0, False), (1, True)]),
    ("crlf-cut-after-cr", b"trial,success\r\n0,False\r", [(0, False), (1, True)]),  # a crash between CR and LF
]


@pytest.mark.parametrize(("before", "after"), [c[1:] for c in APPENDABLE], ids=[c[0] for c in APPENDABLE])
def test_a_hand_saved_log_takes_the_next_trial_on_a_line_of_its_own(tmp_path, before, after):
    log = tmp_path / "deploy_lfdt.csv"
    if before is not None:
        log.write_bytes(before)
    append_trial(log, len(read_trials(log)), True)
    assert read_trials(log) == after
    if before:
        assert log.read_bytes().startswith(before), "a byte of the earlier rows changed"
    # the file's own line ending; CRLF (csv's) for a new file or one with no complete line yet
    ending = (b"\n" if before and b"\n" in before and b"\r\n" not in before
              else b"\r" if before and b"\r" in before and b"\n" not in before else b"\r\n")
    assert log.read_bytes().endswith(b"True" + ending), "the new row does not end with the file's own line ending"


REFUSED = [
    # (id, the file, what the error must name)
    ("other-header", b"trial,outcome\n0,True\n", "header"),
    ("half-a-row-from-a-crash", b"trial,success\r\n0,True\r\n1,Tr", "line 3"),
    ("spreadsheet-bool", b"trial,success\r\n0,TRUE\r\n", "line 2"),
]


@pytest.mark.parametrize(("text", "names"), [c[1:] for c in REFUSED], ids=[c[0] for c in REFUSED])
def test_a_log_that_is_not_one_is_refused_by_file_and_line_and_kept(tmp_path, text, names):
    log = tmp_path / "deploy_lfdt.csv"
    log.write_bytes(text)
    with pytest.raises(DeployLogError, match=names) as err:
        read_trials(log)  # what the deploy command does first, and the twin_evaluate stage
    assert str(log) in str(err.value)
    if names == "header":  # and appending is refused on its own
        with pytest.raises(DeployLogError, match="header"):
            append_trial(log, 1, True)
    assert log.read_bytes() == text


def test_a_failed_write_leaves_the_earlier_rows_as_they_were(tmp_path, monkeypatch):
    """Everything one append adds goes out in one write: when it fails (a full disk, a crash), nothing of it and
    nothing before it is lost or half-written by this module."""
    log = tmp_path / "trials.csv"
    csvlog.append_rows(log, ["a", "b"], [["1", "x"]])
    before = log.read_bytes()

    def fail(fd, data):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(csvlog.os, "write", fail)
    with pytest.raises(OSError, match="No space"):
        csvlog.append_rows(log, ["a", "b"], [["2", "y"], ["3", "z"]])
    assert log.read_bytes() == before


def test_append_rows_keeps_quoting_and_refuses_another_header(tmp_path):
    log = tmp_path / "trials.csv"
    csvlog.append_rows(log, ["trial", "changes"], [["t1", "a=1, b=2"]])
    csvlog.append_rows(log, ["trial", "changes"], [["t2", 'say "x"']])
    assert log.read_text().splitlines() == ["trial,changes", 't1,"a=1, b=2"', 't2,"say ""x"""']
    with pytest.raises(csvlog.CsvLogError, match=f"{log}: header"):
        csvlog.append_rows(log, ["trial", "other"], [["t3", "c"]])
