"""Append-only CSV logs (the real robot's deploy log, the development trials' table): rows are only ever added, one
write at a time, and a file edited by hand or by a spreadsheet (CRLF endings, no newline after its last line) is
appended to without gluing a row onto another.
"""

from __future__ import annotations

import csv
import errno
import io
import os
from pathlib import Path


class CsvLogError(ValueError):
    """A log that cannot be appended to as it is: names the file and what is wrong."""


def _first_line(head: bytes) -> tuple[bytes, str]:
    """The first line of a file (without its ending) and the file's own line ending: CRLF (as :mod:`csv` and
    spreadsheets write it; also the default for a file with no complete line yet), LF, or CR only (old Mac tools)."""
    cut = [i for i in (head.find(b"\r"), head.find(b"\n")) if i >= 0]
    if not cut:
        return head, "\r\n"
    i = min(cut)
    if head[i:i + 1] == b"\n":
        return head[:i], "\n"
    return head[:i], "\r\n" if head[i + 1:i + 2] == b"\n" else "\r"


def _plan(path: Path, header: list[str]) -> tuple[int, str, str]:
    """(size, line ending, what goes before the first new row) of an append to ``path``; CsvLogError when its
    header is another one (or not UTF-8), before anything is written."""
    size = path.stat().st_size if path.exists() else 0
    if size == 0:
        return 0, "\r\n", ""  # csv's own default, as every log this project wrote so far
    with open(path, "rb") as fh:
        head = fh.read(65536)
        fh.seek(size - 1)
        last = fh.read(1)
    first, ending = _first_line(head)
    try:
        text = first.decode("utf-8")
    except UnicodeDecodeError:
        raise CsvLogError(f"{path}, line 1: the header is not UTF-8 text; not appending to it (move it aside to "
                          "start a new log)") from None
    found = next(csv.reader([text]), [])
    if found != header:
        raise CsvLogError(f"{path}: header {found} is not {header}; not appending to it (move it aside to start "
                          "a new log)")
    # a last line without its ending gets one first, in the file's own style; half a CRLF gets its LF
    prefix = "" if last == b"\n" or (last == b"\r" and ending == "\r") else "\n" if last == b"\r" else ending
    return size, ending, prefix


def check_appendable(path: str | Path, header: list[str], what: str = "log") -> Path:
    """Everything :func:`append_rows` needs, checked without writing: the path is a regular file that can be
    appended to (or can be created), its disk is not full (:func:`lfdt.inputs.writable_file`, an InputError), and
    its header is ``header`` (CsvLogError). Call it before the work whose result goes into the log."""
    from lfdt.inputs import writable_file

    path = writable_file(path, what, f"a CSV log with the header {','.join(header)}")
    _plan(path, header)
    return path


def append_rows(path: str | Path, header: list[str], rows: list[list[str]]) -> None:
    """Append ``rows`` to the CSV log at ``path`` (created with ``header`` if missing or empty), durably.

    Everything this call adds goes out in one ``write`` on a descriptor opened for appending, then ``fsync``: a
    crash leaves the earlier rows as they were. When the file's last line has no line ending (a hand-edited file) it
    gets one first, in the file's own style (CRLF, LF or CR only), so the first new row starts a line of its own. A
    file whose header is not ``header`` raises :class:`CsvLogError` naming the file, and nothing is written. A write
    that fails (a full disk) raises OSError naming the file.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    size, ending, prefix = _plan(path, header)
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator=ending)
    if size == 0:
        writer.writerow(header)
    writer.writerows(rows)
    data = (prefix + buf.getvalue()).encode()
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        try:
            written = os.write(fd, data)
            if written != len(data):  # a full disk: say so rather than leave half a row unannounced
                raise OSError(errno.ENOSPC, f"only {written} of {len(data)} bytes could be appended")
            os.fsync(fd)
        except OSError as err:  # the OS names no file for a failed write: name it here
            raise OSError(err.errno, err.strerror or str(err), str(path)) from None
    finally:
        os.close(fd)
