"""Checks of user-given files and folders at the entry points (command lines, stages): one function per kind of
input, each returning what it checked (or read) or raising :class:`~lfdt.errors.InputError` whose message names the
input (``what``: the argument or key, e.g. ``--log``), its path, what is wrong and what was expected.

A command checks every file it will read and every file or folder it will write *before* it starts anything that
costs time or cannot be repeated (a trial on the robots), so that a bad path ends it with one line and exit 2 and
nothing is lost. ``error`` lets a module raise its own subclass (e.g. the deploy log's).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import stat
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

from lfdt import errors
from lfdt.errors import InputError, StageError

T = TypeVar("T")

MIN_FREE_BYTES = 1 << 16
"""Less free space than this on the disk of an output counts as a full disk: a log row needs one block, and a
file system that is full for ordinary users still reports a few free blocks for root."""

_KINDS = ((stat.S_ISDIR, "a folder"), (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
          (stat.S_ISFIFO, "a pipe"), (stat.S_ISSOCK, "a socket"))


def _kind(mode: int) -> str:
    return next((name for test, name in _KINDS if test(mode)), "not a regular file")


def _fail(error: type[InputError], what: str, path: Path, problem: str, expected: str) -> InputError:
    return error(f"{what} {path}: {problem}" + (f"; expected {expected}" if expected else ""))


def _stat(path: Path, what: str, expected: str, error: type[InputError]) -> os.stat_result | None:
    """``os.stat(path)``, None when nothing is there; a path through a file or an unreadable folder raises."""
    try:
        return os.stat(path)
    except FileNotFoundError:
        return None
    except NotADirectoryError:
        raise _fail(error, what, path, "a folder on its path is a file", expected) from None
    except OSError as err:
        raise _fail(error, what, path, f"cannot look at it ({err.strerror or err})", expected) from None


def readable_file(path: str | Path, what: str, expected: str = "", *,
                  error: type[InputError] = InputError) -> Path:
    """``path`` if it is an existing regular file this process may read."""
    path = Path(path)
    st = _stat(path, what, expected, error)
    if st is None:
        raise _fail(error, what, path, "no such file", expected)
    if not stat.S_ISREG(st.st_mode):
        raise _fail(error, what, path, f"is {_kind(st.st_mode)}, not a file", expected)
    if not os.access(path, os.R_OK):
        raise _fail(error, what, path, "cannot read it (permission denied)", expected)
    return path


def decode_utf8(data: bytes, path: str | Path, what: str, expected: str = "", *,
                error: type[InputError] = InputError) -> str:
    """``data`` (the bytes of ``path``) as UTF-8 text; a byte that is not UTF-8 raises, naming its line."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        line = data[:err.start].count(b"\n") + 1
        raise _fail(error, what, Path(path), f"line {line}: byte 0x{data[err.start]:02x} (offset {err.start}) is "
                    "not UTF-8 text", expected) from None


def read_text(path: str | Path, what: str, expected: str = "", *, error: type[InputError] = InputError) -> str:
    """The UTF-8 text of a readable file (:func:`readable_file`, :func:`decode_utf8`)."""
    path = readable_file(path, what, expected, error=error)
    try:
        data = path.read_bytes()
    except OSError as err:
        raise _fail(error, what, path, f"cannot read it ({err.strerror or err})", expected) from None
    return decode_utf8(data, path, what, expected, error=error)


def json_object(path: str | Path, what: str, expected: str, parse: Callable[[dict], T] | None = None, *,
                error: type[InputError] = InputError) -> dict | T:
    """The JSON object in a file, or ``parse(obj)`` of it. Empty, not JSON, JSON of another type (a list, a
    number), or refused by ``parse`` (KeyError: a missing key; TypeError, ValueError, IndexError: a value of the
    wrong type or shape) raises, naming the file and ``expected``."""
    path = Path(path)
    text = read_text(path, what, expected, error=error)
    if not text.strip():
        raise _fail(error, what, path, "is empty", expected)
    try:
        obj: Any = json.loads(text)
    except json.JSONDecodeError as err:
        raise _fail(error, what, path, f"is not JSON (line {err.lineno} column {err.colno}: {err.msg})",
                    expected) from None
    if not isinstance(obj, dict):
        raise _fail(error, what, path, f"holds a JSON {_json_type(obj)}, not an object", expected)
    twice = duplicate_json_key(text)
    if twice is not None:
        raise _fail(error, what, path, f"has the key {twice!r} twice in one object", expected)
    if parse is None:
        return obj
    try:
        return parse(obj)
    except KeyError as err:
        raise _fail(error, what, path, f"has no key {err.args[0]!r}", expected) from None
    except (TypeError, ValueError, IndexError) as err:
        raise _fail(error, what, path, errors.first_line(err), expected) from None


class _Twice(Exception):
    pass


def _no_key_twice(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise _Twice(key)
        out[key] = value
    return out


def duplicate_json_key(text: str) -> str | None:
    """The first key written twice in one object of the JSON ``text`` (which parses), or None. JSON parsers keep
    the last one without a word, so a value added above an existing key would silently lose."""
    try:
        json.loads(text, object_pairs_hook=_no_key_twice)
    except _Twice as twice:
        return twice.args[0]
    return None


def _json_type(obj: Any) -> str:
    names = {list: "list", str: "string", bool: "boolean", int: "number", float: "number", type(None): "null"}
    return names.get(type(obj), type(obj).__name__)


def _creatable_in(path: Path, what: str, expected: str, error: type[InputError]) -> Path:
    """The nearest existing folder above ``path`` (which does not exist), checked writable: where it will be made."""
    for parent in path.absolute().parents:
        st = _stat(parent, what, expected, error)
        if st is None:
            continue
        if not stat.S_ISDIR(st.st_mode):
            raise _fail(error, what, path, f"{parent} is {_kind(st.st_mode)}, not a folder", expected)
        if not os.access(parent, os.W_OK | os.X_OK):
            raise _fail(error, what, path, f"cannot create it in {parent} (permission denied)", expected)
        return parent
    raise _fail(error, what, path, "no folder above it exists", expected)  # unreachable: / exists


def _has_space(folder: Path, path: Path, what: str, expected: str, error: type[InputError]) -> None:
    try:
        st = os.statvfs(folder)
    except OSError:
        return  # a file system that cannot tell: the write itself will say
    if st.f_blocks == 0:  # procfs, sysfs: no disk behind them, so "0 bytes free" would say the wrong thing
        raise _fail(error, what, path, "is on a virtual file system (such as /proc or /sys), which keeps no files",
                    expected)
    free = st.f_bavail * st.f_frsize
    if free < MIN_FREE_BYTES:
        raise _fail(error, what, path, f"the disk holding it is full ({free} bytes free)", expected)


def writable_file(path: str | Path, what: str, expected: str = "", *, error: type[InputError] = InputError) -> Path:
    """``path`` if it is a regular file this process may read and append to, or can be created (its folders
    included), on a disk that is not full. Devices are refused: ``/dev/full`` opens but every write to it fails,
    and what goes to ``/dev/null`` cannot be read back."""
    path = Path(path)
    st = _stat(path, what, expected, error)
    if st is None:
        folder = _creatable_in(path, what, expected, error)
    else:
        if not stat.S_ISREG(st.st_mode):
            raise _fail(error, what, path, f"is {_kind(st.st_mode)}, not a file", expected)
        if not os.access(path, os.R_OK | os.W_OK):
            raise _fail(error, what, path, "cannot write it (permission denied)", expected)
        folder = path.absolute().parent
    _has_space(folder, path, what, expected, error)
    return path


def output_folder(path: str | Path, what: str, expected: str = "", *,
                  error: type[InputError] = InputError) -> Path:
    """``path`` if it is a folder this process may write in, or can be created, on a disk that is not full."""
    path = Path(path)
    st = _stat(path, what, expected, error)
    if st is None:
        _creatable_in(path, what, expected, error)
        folder = path
        while not folder.exists():
            folder = folder.absolute().parent
    else:
        if not stat.S_ISDIR(st.st_mode):
            problem = "is a file" if stat.S_ISREG(st.st_mode) else f"is {_kind(st.st_mode)}"
            raise _fail(error, what, path, f"{problem}, not a folder", expected)
        if not os.access(path, os.W_OK | os.X_OK):
            raise _fail(error, what, path, "cannot write in it (permission denied)", expected)
        folder = path
    _has_space(folder, path, what, expected, error)
    return path


def os_error_message(err: OSError, what: str = "") -> str:
    """One line for an OSError that reached an entry point: the path (or ``what``, when the OS named none, as for a
    failed write) and the OS's reason, without the ``[Errno N]`` prefix, then any notes the code added to it."""
    names = [str(n) for n in (err.filename, err.filename2) if n is not None]
    where = " -> ".join(names) or what
    reason = err.strerror or str(err)
    return "; ".join([f"{where}: {reason}" if where else reason, *getattr(err, "__notes__", [])])


def camera_device(index: int, what: str, *, error: type[InputError] = InputError) -> int:
    """``index`` if it names a camera on this machine: on Linux (V4L2) the device ``/dev/video<index>`` exists;
    elsewhere only that it is >= 0 (opening the camera tells the rest)."""
    if index < 0:
        raise error(f"{what} {index}: a camera index is >= 0")
    if sys.platform.startswith("linux"):
        device = Path(f"/dev/video{index}")
        if not device.exists():
            present = sorted(str(p) for p in Path("/dev").glob("video*"))
            raise error(f"{what} {index}: no camera {device} on this machine (cameras: "
                        f"{', '.join(present) or 'none'}); expected the index of a connected camera or a video file")
    return index


# Environment variables, network services and databases: the same family for what comes from outside the files.
# lfdt.numerics imports this module before numpy, torch or mujoco load, so nothing heavy is imported at its top.


def env_choice(name: str, choices: tuple[str, ...], default: str, *, error: type[InputError] = InputError) -> str:
    """The value of environment variable ``name`` (case and spaces ignored; unset or empty: ``default``) if it is one
    of ``choices``."""
    raw = os.environ.get(name)
    value = (raw or "").strip().lower() or default
    if value not in choices:
        raise error(f"{name}={raw!r}: expected one of {', '.join(choices)} (unset: {default})")
    return value


def env_text(name: str, default: str, max_len: int, why: str = "", *, error: type[InputError] = InputError) -> str:
    """The value of environment variable ``name`` (unset or empty: ``default``) if it has at most ``max_len``
    characters and no control character (a newline would split the one-line messages and logs that name it);
    ``why`` says where the limit comes from."""
    value = os.environ.get(name) or default
    if len(value) > max_len:
        raise error(f"{name} is {len(value)} characters long ({value[:20]!r}...); expected at most {max_len}"
                    + (f" ({why})" if why else ""))
    bad = next((c for c in value if ord(c) < 32 or ord(c) == 127), None)
    if bad is not None:
        raise error(f"{name}={value!r}: holds the control character {bad!r}; expected printable text")
    return value


def http_answers(url: str, what: str, timeout_s: float, probe_path: str = "", hint: str = "", *,
                 error: type[InputError] = InputError) -> int:
    """The HTTP status with which the server at ``url`` answers a GET of ``probe_path`` (appended to its path; a user
    name and password in ``url`` are left out) within ``timeout_s`` seconds. No answer, or an answer of 5xx (the
    server or what stands behind it is down: a client would retry for minutes), raises ``error``: ``what`` (naming
    the variable and its URL) ``does not answer ...``, then ``hint``. An answer over TLS that this process cannot
    verify counts as one (the client checks certificates its own way)."""
    import ssl
    import urllib.error
    import urllib.request
    from urllib.parse import urlsplit, urlunsplit

    tail = f"; {hint}" if hint else ""
    try:
        parts = urlsplit(url)
        parts.port  # noqa: B018 - raises for a port that is no number from 0 to 65535
    except ValueError as err:
        raise error(f"{what}: not a URL that can be read ({err}){tail}") from None
    netloc = parts.netloc.rsplit("@", 1)[-1]  # user:password@ is the client's basic auth, not the address
    probe = urlunsplit((parts.scheme, netloc, parts.path.rstrip("/") + probe_path, "", ""))
    try:
        with urllib.request.urlopen(probe, timeout=timeout_s) as resp:
            return resp.status
    except urllib.error.HTTPError as err:
        if err.code < 500:
            return err.code  # it answers (a proxy, another version, a login): the client takes it from here
        raise error(f"{what} answers HTTP {err.code} ({err.reason}) to GET {probe_path or '/'}: the server, or "
                    f"what stands behind it, is down{tail}") from None
    except (urllib.error.URLError, OSError, ValueError) as err:
        reason = getattr(err, "reason", err)
        if isinstance(reason, ssl.SSLError):
            return 0
        raise error(f"{what} does not answer within {timeout_s:g} s ({reason}){tail}") from None


GRPC_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + b"\x00\x00\x00\x04\x00\x00\x00\x00\x00"
"""What an HTTP/2 (gRPC) client sends first: the connection preface and an empty SETTINGS frame; a server answers
with a SETTINGS frame of its own (a 9-byte frame header of type 4 on stream 0)."""


def tcp_service(address: str, what: str, protocol: str, timeout_s: float, *, default_port: int | None = None,
                reply_s: float = 3.0, hint: str = "", error: type[InputError] = InputError) -> None:
    """Check that ``address`` (``host:port`` or a URL) accepts a connection within ``timeout_s`` seconds
    (:func:`lfdt.reach.check`) and speaks ``protocol`` there, answering within ``reply_s`` seconds once connected (a
    server answers a handshake in a round trip): ``grpc`` (HTTP/2: Ray's head and its client server) or ``tcp`` (a
    connection is enough). Another service on the port (a web server, a database, a program that says
    nothing) would leave its client waiting for minutes; it raises ``error`` naming ``what``, the address and what
    came back, then ``hint``."""
    import socket

    from lfdt.reach import check, host_port, redact

    check(address, what, default_port=default_port, timeout=timeout_s)
    if protocol == "tcp":
        return
    if protocol != "grpc":
        raise ValueError(f"unknown protocol {protocol!r}")
    host, port = host_port(address, default_port)
    at = redact(address) + ("" if address == f"{host}:{port}" else f" ({host}:{port})")
    expected = f"expected a gRPC server (HTTP/2){f'; {hint}' if hint else ''}"
    try:
        with socket.create_connection((host, port), timeout=timeout_s) as sock:
            sock.settimeout(min(reply_s, timeout_s))
            sock.sendall(GRPC_PREFACE)
            reply = b""
            while len(reply) < 9:
                chunk = sock.recv(64)
                if not chunk:
                    break
                reply += chunk
    except TimeoutError:
        raise error(f"{what} at {at} accepts a connection but says nothing within {min(reply_s, timeout_s):g} s; "
                    f"{expected}") from None
    except OSError as err:
        raise error(f"{what} at {at} accepts a connection, then {(err.strerror or type(err).__name__).lower()}; "
                    f"{expected}") from None
    if len(reply) < 9 or reply[3] != 0x04 or reply[5:9] != b"\x00\x00\x00\x00":
        said = f"answers {reply[:40]!r}" if reply else "closes it without a word"
        raise error(f"{what} at {at} accepts a connection but {said}; {expected}")


def sqlite_answers(path: str | Path, what: str, thorough: bool = False, timeout_s: float = 5.0, *,
                   error: type[InputError] = InputError) -> None:
    """Check that the SQLite database ``path`` (existing) answers queries: opened read-only, its tables listed and
    MLflow's ``experiments`` and ``runs`` counted where it has them; ``thorough`` adds ``PRAGMA quick_check``
    (every page: a second per few hundred MB). A header that is intact in a file cut short (a copy interrupted, a
    full disk) passes a look at the first bytes, and fails here. A database locked by a writer counts as
    answering."""
    import sqlite3

    path = Path(path)
    hint = "; move it aside (a new store starts) or restore it from a backup"
    try:
        con = sqlite3.connect(f"{path.absolute().as_uri()}?mode=ro", uri=True, timeout=timeout_s)
    except sqlite3.Error as err:
        raise error(f"{what}: {path} cannot be opened ({err}){hint}") from None
    try:
        tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        for table in ("experiments", "runs"):
            if table in tables:
                con.execute(f"SELECT count(*) FROM {table}").fetchone()
        if thorough:
            problems = [r[0] for r in con.execute("PRAGMA quick_check(3)")]
            if problems != ["ok"]:
                raise error(f"{what}: {path} is damaged (SQLite's quick_check: {'; '.join(problems)}){hint}")
    except sqlite3.OperationalError as err:
        text = str(err).lower()
        if "malformed" in text or "i/o error" in text or "not a database" in text:
            raise error(f"{what}: {path} does not answer a query ({err}){hint}") from None
        # locked by a writer, or a crashed writer's journal that a read-only connection may not roll back: the
        # store's own client (which writes) copes with both
    except sqlite3.DatabaseError as err:
        raise error(f"{what}: {path} does not answer a query ({err}: the file is damaged or cut short){hint}") from None
    finally:
        con.close()


def one_line_errors(body: Callable[[], int], interrupted: str,
                    refused: tuple[type[Exception], ...] = ()) -> int:
    """Run a command line's ``body`` (its exit code): a :class:`StageError`, one of ``refused`` (e.g. a params
    problem) or an OSError (a full disk, no permission: :func:`os_error_message`) is
    one line and exit 2, Ctrl-C one line saying ``interrupted`` (what is left, how to go on) and
    :data:`lfdt.errors.INTERRUPTED`; anything else is a bug and raises."""
    try:
        return body()
    except (StageError, *refused) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"error: interrupted (Ctrl-C): {interrupted}", file=sys.stderr)
        return errors.INTERRUPTED
    except OSError as err:
        print(f"error: {os_error_message(err)}", file=sys.stderr)
        return 2


# ------------------------------------------------------------------- argparse: the parser and its argument types


class ArgumentParser(argparse.ArgumentParser):
    """argparse's parser whose refusal of a command line is one line, as every other refusal is: ``error: <prog>:
    <what>; <prog> --help lists the options`` and exit 2, without the usage lines argparse prints first. Its
    subcommands' parsers are of this class too."""

    def error(self, message: str):  # noqa: D102 - argparse's hook
        self.exit(2, f"error: {self.prog}: {' '.join(message.split())}; `{self.prog} --help` lists the options\n")


def positive_int(text: str) -> int:
    """argparse type: an integer >= 1 (a count of episodes, steps, attempts, trials, frames)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value} is not a positive count (>= 1)")
    return value


def tcp_port(text: str) -> int:
    """argparse type: a TCP port, 1..65535."""
    value = positive_int(text)
    if value > 65535:
        raise argparse.ArgumentTypeError(f"{value} is not a TCP port (1..65535)")
    return value


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None


def positive_float(text: str) -> float:
    """argparse type: a finite number > 0 (a distance, a duration)."""
    value = _number(text)
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"{text} is not a positive finite number")
    return value


def nonnegative_float(text: str) -> float:
    """argparse type: a finite number >= 0."""
    value = _number(text)
    if not math.isfinite(value) or value < 0:
        raise argparse.ArgumentTypeError(f"{text} is not a finite number >= 0")
    return value
