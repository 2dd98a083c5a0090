"""Connecting to a Dask cluster: the scheduler's address checked, a time limit on the
connection, and one line naming the address when anything is wrong.

``dask.distributed`` alone does badly with a wrong address: pointed at the dashboard's
HTTP port (8787 instead of 8786) it waits for an answer that never comes (past 150 s),
and pointed at a server that answers in another protocol it reads the first eight bytes
of the answer as a message length and tries to allocate exabytes (``MemoryError``). So
before Dask connects, :func:`check_scheduler` opens a plain TCP connection and reads what
a Dask scheduler says first (it sends its handshake as soon as a connection is accepted:
an 8-byte message length, then the message), all within the time limit:

* an address that does not parse (no host, a port out of range, a scheme Dask does not
  speak) is refused before any connection;
* a refused or unreachable port, a host that does not resolve, or no answer within the
  limit (an HTTP server waits for a request: the dashboard) is one line naming the
  address and the likely cause;
* an answer that is not a Dask handshake is one line as well.

The limit (:data:`DEFAULT_TIMEOUT_S`) is set by ``run_corpus(scheduler_timeout=)``,
``--scheduler-timeout`` or ``CASSI_SCHEDULER_TIMEOUT`` (seconds) and also bounds Dask's
own connection.
"""

from __future__ import annotations

import os
import socket
import struct
from dataclasses import dataclass
from typing import Any

from ..errors import CassiError

#: Seconds allowed for reaching the scheduler and for Dask's connection to it.
DEFAULT_TIMEOUT_S = 10.0
TIMEOUT_ENV = "CASSI_SCHEDULER_TIMEOUT"
DEFAULT_PORT = 8786  # Dask's scheduler port (its dashboard is 8787, HTTP)
#: Schemes Dask's client speaks over TCP; only ``tcp`` handshakes are checked byte-wise
#: (the others are encrypted or framed before Dask's first message).
SCHEMES = ("tcp", "tls", "ws", "wss")
#: Dask's other transports (one process's own cluster, UCX networks): passed to Dask as
#: they are, with its connection bounded by the time limit.
OTHER_SCHEMES = ("inproc", "ucx")
_LARGEST_HANDSHAKE = 1 << 20  # bytes: a scheduler's first message is a few hundred


class SchedulerError(CassiError):
    """The Dask scheduler address is wrong or nothing usable answers there."""


@dataclass(frozen=True)
class SchedulerAddress:
    """A parsed scheduler address: ``scheme://host:port``."""

    scheme: str
    host: str
    port: int

    def __str__(self) -> str:
        if self.scheme in OTHER_SCHEMES:
            return f"{self.scheme}://{self.host}"
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{self.scheme}://{host}:{self.port}"


def scheduler_timeout(timeout: float | None = None) -> float:
    """The connection time limit in seconds: ``timeout`` if given, else
    ``CASSI_SCHEDULER_TIMEOUT``, else :data:`DEFAULT_TIMEOUT_S`; one error if it is not a
    positive number."""
    given = timeout if timeout is not None else os.environ.get(TIMEOUT_ENV)
    if given is None:
        return DEFAULT_TIMEOUT_S
    try:
        value = float(given)
    except (TypeError, ValueError):
        value = float("nan")
    if not value > 0 or value == float("inf"):
        where = TIMEOUT_ENV if timeout is None else "the scheduler timeout"
        raise CassiError(f"{where} must be a positive number of seconds, got {given!r}")
    return value


def parse_scheduler_address(address: str) -> SchedulerAddress:
    """``[scheme://]host[:port]`` checked: a scheme Dask speaks over TCP (default
    ``tcp``), a host, a port in 1..65535 (default 8786); else :class:`SchedulerError`."""
    text = str(address).strip()
    if not text:
        raise SchedulerError("--scheduler: empty address (e.g. tcp://host:8786)")
    scheme, sep, rest = text.partition("://")
    if not sep:
        scheme, rest = "tcp", text
    scheme = scheme.lower()
    if scheme in OTHER_SCHEMES and rest:
        return SchedulerAddress(scheme, rest, 0)
    if scheme not in SCHEMES:
        raise SchedulerError(f"{address}: not a Dask scheduler address (scheme {scheme!r}; "
                             f"use {', '.join(s + '://' for s in SCHEMES)}, e.g. "
                             f"tcp://host:{DEFAULT_PORT})")
    rest = rest.rstrip("/")
    if rest.startswith("["):  # [IPv6]:port
        host, _, tail = rest[1:].partition("]")
        port_text = tail[1:] if tail.startswith(":") else tail
    elif rest.count(":") == 1:
        host, port_text = rest.split(":")
    else:
        host, port_text = rest, ""
    if not host or "/" in host or any(c.isspace() for c in host):
        raise SchedulerError(f"{address}: no host in the scheduler address "
                             f"(e.g. tcp://host:{DEFAULT_PORT})")
    if not port_text:
        port = DEFAULT_PORT
    elif port_text.isdigit() and 0 < int(port_text) < 65536:
        port = int(port_text)
    else:
        raise SchedulerError(f"{address}: the port must be a number in 1..65535, "
                             f"got {port_text!r}")
    return SchedulerAddress(scheme, host, port)


def check_scheduler(address: str, timeout: float | None = None) -> SchedulerAddress:
    """Check that a Dask scheduler answers at ``address`` within ``timeout`` seconds
    (:func:`scheduler_timeout`); returns the parsed address or raises one-line
    :class:`SchedulerError` naming it (see the module's doc)."""
    where = parse_scheduler_address(address)
    limit = scheduler_timeout(timeout)
    if where.scheme in OTHER_SCHEMES:
        return where
    try:
        sock = socket.create_connection((where.host, where.port), timeout=limit)
    except socket.gaierror as exc:
        raise SchedulerError(f"{where}: host {where.host!r} not found ({exc.strerror})"
                             ) from None
    except TimeoutError:
        raise SchedulerError(f"{where}: no answer within {limit:g} s (host down or "
                             f"port filtered?)") from None
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise SchedulerError(f"{where}: cannot connect ({reason}); is a Dask scheduler "
                             f"running there?") from None
    with sock:
        if where.scheme == "tcp":
            _read_handshake(sock, where, limit)
    return where


def _read_handshake(sock: socket.socket, where: SchedulerAddress, limit: float) -> None:
    """The first 8 bytes a scheduler sends: its handshake's length (native uint64)."""
    sock.settimeout(limit)
    head = b""
    try:
        while len(head) < 8:
            chunk = sock.recv(8 - len(head))
            if not chunk:
                raise SchedulerError(f"{where}: the server closed the connection without "
                                     "a Dask handshake; not a Dask scheduler")
            head += chunk
    except TimeoutError:
        raise SchedulerError(
            f"{where}: connected, but no Dask handshake within {limit:g} s: not a Dask "
            f"scheduler (a web server such as the dashboard, usually port 8787, waits "
            f"silently; the scheduler's port is usually {DEFAULT_PORT})") from None
    except OSError as exc:
        raise SchedulerError(f"{where}: connection lost ({exc.strerror or exc})") from None
    (length,) = struct.unpack("Q", head)
    if not 0 < length < _LARGEST_HANDSHAKE:
        shown = head.decode("ascii", "replace").strip() or head.hex()
        raise SchedulerError(f"{where}: the server answered {shown!r}..., not a Dask "
                             "handshake; not a Dask scheduler")


def connect_scheduler(address: str, timeout: float | None = None) -> Any:
    """A ``distributed.Client`` connected to the scheduler at ``address``, after
    :func:`check_scheduler`, with Dask's connection bounded by the same time limit. Without
    the ``corpus`` extra: one line saying which to install."""
    try:
        from distributed import Client
    except ModuleNotFoundError:
        raise CassiError("--scheduler needs dask.distributed: install the 'corpus' extra "
                         "(pip install 'cassi_fit[corpus]')") from None
    where = check_scheduler(address, timeout)
    limit = scheduler_timeout(timeout)
    try:
        return Client(str(where), timeout=limit)
    except (OSError, TimeoutError) as exc:
        text = " ".join(str(exc).split()) or type(exc).__name__
        raise SchedulerError(f"{where}: Dask could not connect within {limit:g} s "
                             f"({text})") from None
