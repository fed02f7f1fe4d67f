"""uvicorn's h11 protocol with the connection bounds a public server needs.

uvicorn has a keep-alive timeout but nothing for a connection that never finishes its request
header (20,000 idle connections take a server down), and it answers malformed requests with
plain text. :func:`guarded_protocol` returns an ``H11Protocol`` subclass that

* keeps at most ``max_connections`` open, ``max_per_client`` of them per client address: a
  new connection evicts the oldest *idle* one (no request in progress) of its own address
  when that address is at its bound, else the oldest idle one of any address when the server
  is full. So a flood of idle connections from one client evicts only its own, and never
  locks out a health probe or another client; only when every candidate is busy is the new
  connection closed at once (at most one warning per second is logged, not one per
  connection);
* gives every request ``header_timeout`` seconds from its first byte (or from the connection's
  start) to complete its header, then closes the connection (slowloris);
* answers protocol-level errors (bad request line, oversized header) as
  ``application/problem+json`` with ``Connection: close``.

Request bodies are bounded in size and time by :class:`service.api.http.limits.BodyLimitMiddleware`,
idle keep-alive connections by uvicorn's ``timeout_keep_alive``.
"""

from __future__ import annotations

import asyncio
import json
import sys
import time
from collections import OrderedDict
from typing import Any, ClassVar

import h11
from uvicorn.protocols.http.h11_impl import H11Protocol

from service.api.http.logs import get_logger

__all__ = ["guarded_protocol"]

log = get_logger("geosmooth.api")


class _Refusals:
    """Counts refused connections; logs at most once per second."""

    def __init__(self) -> None:
        self.count = 0
        self.last_log = 0.0

    def add(self, open_connections: int) -> None:
        self.count += 1
        now = time.monotonic()
        if now - self.last_log >= 1.0:
            log.warning("connections.refused", refused=self.count, open=open_connections)
            self.count, self.last_log = 0, now


class GuardedH11Protocol(H11Protocol):
    """See the module docstring; configured by :func:`guarded_protocol`."""

    max_connections: int = 2048
    max_per_client: int = 256
    header_timeout: float = 10.0
    refusals = _Refusals()
    #: Connections without a request in progress, oldest first (one set per server class).
    idle: ClassVar[OrderedDict[GuardedH11Protocol, None]] = OrderedDict()
    #: Open connections per client address.
    per_client: ClassVar[dict[str, int]] = {}

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self._header_timer: asyncio.TimerHandle | None = None
        self._address = self.client[0] if self.client else "-"
        self._counted = False
        self._refused: tuple[int, str] | None = None
        mine = self.per_client.get(self._address, 0)
        if mine >= self.max_per_client:
            room = self._evict_idle(self._address)
        else:
            room = len(self.connections) <= self.max_connections or self._evict_idle(None)
        if not room:  # answered once its request header has come (see _refuse)
            self.refusals.add(len(self.connections))
            self._refused = (429, "this client") if mine >= self.max_per_client else (503, "")
            self._arm_header_timer()
            return
        self.per_client[self._address] = self.per_client.get(self._address, 0) + 1
        self._counted = True
        self.idle[self] = None
        self._arm_header_timer()

    def _evict_idle(self, address: str | None) -> bool:
        """Close the oldest idle connection (of ``address``, if given); ``False`` if none."""
        victim = next((c for c in self.idle if address is None or c._address == address), None)
        if victim is None:
            return False
        del self.idle[victim]
        self.refusals.add(len(self.connections))
        victim.transport.abort()
        return True

    def _arm_header_timer(self) -> None:
        if self._header_timer is None:
            self._header_timer = self.loop.call_later(self.header_timeout, self._header_expired)

    def _disarm_header_timer(self) -> None:
        if self._header_timer is not None:
            self._header_timer.cancel()
            self._header_timer = None

    def _refuse(self) -> None:
        """Answer a connection over the bounds: 429 (its address is at its bound) or 503
        (the server is full), ``Retry-After`` and ``Connection: close``, then close it.

        Sent after the request header has arrived, so that the client reads the answer
        instead of a reset."""
        status, who = self._refused or (503, "")
        detail = (
            f"too many open connections from {who}; close some (e.g. event streams) and retry"
            if status == 429
            else "the server has too many open connections; retry shortly"
        )
        code = "too-many-connections" if status == 429 else "server-busy"
        _write_problem(self.transport, status, detail, code, retry_after=_RETRY_AFTER)

    def data_received(self, data: bytes) -> None:
        if self._refused is not None:
            if b"\r\n\r\n" in data or b"\n\n" in data or len(data) > 16384:
                self._disarm_header_timer()
                self._refuse()
            return
        if self.conn.their_state is h11.IDLE:
            self._arm_header_timer()
        super().data_received(data)
        if self.conn.their_state is not h11.IDLE:
            self._disarm_header_timer()
            self.idle.pop(self, None)

    def handle_events(self) -> None:
        super().handle_events()
        cycle = getattr(self, "cycle", None)
        if cycle is not None and _framed_twice(getattr(self, "headers", [])):
            cycle.keep_alive = False  # RFC 9112 section 6.1: close after responding

    def on_response_complete(self) -> None:
        super().on_response_complete()
        self._disarm_header_timer()  # idle from here on: uvicorn's keep-alive timeout applies
        if not self.transport.is_closing() and self.conn.their_state is h11.IDLE:
            self.idle[self] = None

    def _header_expired(self) -> None:
        self._header_timer = None
        if self.conn.their_state is h11.IDLE and not self.transport.is_closing():
            self.transport.close()

    def connection_lost(self, exc: Exception | None) -> None:
        self._disarm_header_timer()
        self.idle.pop(self, None)
        if self._counted:
            self._counted = False
            left = self.per_client.get(self._address, 1) - 1
            if left > 0:
                self.per_client[self._address] = left
            else:
                self.per_client.pop(self._address, None)
        super().connection_lost(exc)

    def send_400_response(self, msg: str) -> None:
        error = sys.exc_info()[1]
        status = getattr(error, "error_status_hint", 400) or 400
        detail = f"invalid HTTP request: {error}" if error else msg
        body = json.dumps(
            {
                "type": "urn:geosmooth:problem:malformed-request",
                "title": "Request Header Fields Too Large" if status == 431 else "Bad Request",
                "status": status,
                "detail": detail,
                "code": "malformed-request",
            }
        ).encode()
        headers = [
            (b"content-type", b"application/problem+json"),
            (b"content-length", str(len(body)).encode()),
            (b"connection", b"close"),
        ]
        try:
            for event in (
                h11.Response(status_code=status, headers=headers),
                h11.Data(data=body),
                h11.EndOfMessage(),
            ):
                self.transport.write(self.conn.send(event))  # type: ignore[arg-type]
        except h11.LocalProtocolError:  # the response had already started
            pass
        self.transport.close()


_RETRY_AFTER = 2


def _framed_twice(headers: list[tuple[bytes, bytes]]) -> bool:
    """Both ``Content-Length`` and ``Transfer-Encoding``: h11 frames the body by the latter,
    and the connection must close after the response (a request smuggling vector)."""
    names = {name for name, _ in headers}
    return b"content-length" in names and b"transfer-encoding" in names


def _write_problem(
    transport: asyncio.BaseTransport, status: int, detail: str, code: str, retry_after: int
) -> None:
    """A complete problem+json answer written straight to ``transport``, which is then closed."""
    title = {429: "Too Many Requests", 503: "Service Unavailable"}[status]
    body = json.dumps(
        {
            "type": f"urn:geosmooth:problem:{code}",
            "title": title,
            "status": status,
            "detail": detail,
            "code": code,
            "retry_after": retry_after,
        }
    ).encode()
    head = (
        f"HTTP/1.1 {status} {title}\r\ncontent-type: application/problem+json\r\n"
        f"content-length: {len(body)}\r\nretry-after: {retry_after}\r\n"
        "x-content-type-options: nosniff\r\nconnection: close\r\n\r\n"
    ).encode()
    assert isinstance(transport, asyncio.WriteTransport)
    transport.write(head + body)
    transport.close()


def guarded_protocol(max_connections: int, max_per_client: int, header_timeout: float) -> type[Any]:
    """A :class:`GuardedH11Protocol` subclass with these bounds (for ``uvicorn.Config``)."""
    return type(
        "GeosmoothH11Protocol",
        (GuardedH11Protocol,),
        {
            "max_connections": max_connections,
            "max_per_client": max_per_client,
            "header_timeout": header_timeout,
            "per_client": {},
            "refusals": _Refusals(),
            "idle": OrderedDict(),
        },
    )
