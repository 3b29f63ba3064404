"""Is a remote service there? One TCP connection with a timeout of seconds, made before any work depends on it, so
that a wrong address ends in one line that names it instead of minutes of a client's retries."""

from __future__ import annotations

import re
import socket
from urllib.parse import urlsplit

from lfdt.errors import StageError

TIMEOUT_S = 5.0
"""How long a service may take to accept a connection: generous for a cluster's network, short beside the minutes
some clients (Ray, MLflow, boto) retry before giving up."""

DEFAULT_PORTS: dict[str, int] = {"http": 80, "https": 443, "s3": 443, "postgresql": 5432, "postgres": 5432,
                                 "mysql": 3306, "mssql": 1433, "ray": 10001}
"""The port a URL of each scheme means when it names none (the part before any ``+driver``)."""


class Unreachable(StageError):
    """A service this run needs does not accept a connection at its address."""


def redact(address: str) -> str:
    """The address with any password replaced by ``***`` (addresses go into error messages and logs)."""
    try:
        password = urlsplit(address).password
    except ValueError:  # not a URL Python can split (an unclosed [IPv6]): hide whatever stands between ':' and '@'
        return re.sub(r"(://[^/@:]*:)[^/@]*@", r"\1***@", address, count=1)
    if password is None:
        return address
    return address.replace(f":{password}@", ":***@", 1)


def host_port(address: str, default_port: int | None = None) -> tuple[str, int]:
    """Host and port of ``host:port`` or of a URL (``http://host:port/...``, ``postgresql://user:pw@host/db``); the
    scheme's usual port (:data:`DEFAULT_PORTS`) or ``default_port`` where it names none. ValueError if it names no
    host."""
    parts = urlsplit(address if "://" in address else f"//{address}")
    scheme = parts.scheme.split("+")[0]
    try:
        port = parts.port
    except ValueError:
        raise ValueError(f"{redact(address)!r}: the port is not a number from 0 to 65535") from None
    port = port if port is not None else DEFAULT_PORTS.get(scheme, default_port)
    if not parts.hostname or port is None:
        raise ValueError(f"{redact(address)!r} names no host:port")
    return parts.hostname, port


def check(address: str, what: str, *, default_port: int | None = None, timeout: float = TIMEOUT_S) -> None:
    """Connect to ``address`` (``host:port`` or a URL) and close again; :class:`Unreachable` names ``what`` is
    there and the address when nothing accepts within ``timeout`` seconds, or when the address names no host."""
    try:
        host, port = host_port(address, default_port)
    except ValueError as err:
        raise Unreachable(f"{what}: {err}") from None
    try:
        with socket.create_connection((host, port), timeout=timeout):
            pass
    except OSError as err:
        reason = "no answer" if isinstance(err, TimeoutError) else (err.strerror or type(err).__name__).lower()
        raise Unreachable(f"{what} at {redact(address)} does not accept a connection on {host}:{port} within "
                          f"{timeout:g} s ({reason}): is it running, and is the address right?") from None
