"""Append-only CSV logs (the real robot's deploy log, the development trials' table): rows are only ever added, one
write at a time, and a file edited by hand or by a spreadsheet (CRLF endings, no newline after its last line) is
appended to without gluing a row onto another.
"""

from __future__ import annotations

import csv
import io
import os
from pathlib import Path


class CsvLogError(ValueError):
    """A log that cannot be appended to as it is: names the file and what is wrong."""


def _line_ending(head: bytes) -> str:
    """The file's own line ending, from its first line (CRLF when it was written by :mod:`csv` or a spreadsheet)."""
    first = head.split(b"\n", 1)[0]
    return "\r\n" if first.endswith(b"\r") or b"\n" not in head else "\n"


def append_rows(path: str | Path, header: list[str], rows: list[list[str]]) -> None:
    """Append ``rows`` to the CSV log at ``path`` (created with ``header`` if missing or empty), durably.

    Everything this call adds goes out in one ``write`` on a descriptor opened for appending, then ``fsync``: a
    crash leaves the earlier rows as they were. When the file's last line has no line ending (a hand-edited file) it
    gets one first, in the file's own style, so the first new row starts a line of its own. A file whose header is
    not ``header`` raises :class:`CsvLogError` naming the file, and nothing is written.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    size = path.stat().st_size if path.exists() else 0
    prefix = ""
    if size == 0:
        ending = "\r\n"  # csv's own default, as every log this project wrote so far
    else:
        with open(path, "rb") as fh:
            head = fh.read(4096)
            fh.seek(size - 1)
            last = fh.read(1)
        ending = _line_ending(head)
        found = next(csv.reader([head.split(b"\n", 1)[0].decode("utf-8", "replace").rstrip("\r")]), [])
        if found != header:
            raise CsvLogError(f"{path}: header {found} is not {header}; not appending to it (move it aside to start "
                              "a new log)")
        if last != b"\n":
            prefix = ending
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator=ending)
    if size == 0:
        writer.writerow(header)
    writer.writerows(rows)
    data = (prefix + buf.getvalue()).encode()
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        written = os.write(fd, data)
        if written != len(data):  # a full disk: say so rather than leave half a row unannounced
            raise OSError(f"{path}: only {written} of {len(data)} bytes could be appended")
        os.fsync(fd)
    finally:
        os.close(fd)
