"""uvicorn's h11 protocol with the connection bounds a public server needs.

uvicorn has a keep-alive timeout but nothing for a connection that never finishes its request
header (20,000 idle connections take a server down), and it answers malformed requests with
plain text. :func:`guarded_protocol` returns an ``H11Protocol`` subclass that

* closes a connection at once while ``max_connections`` are open (no request is read from it;
  at most one warning per second is logged, not one per connection);
* gives every request ``header_timeout`` seconds from its first byte (or from the connection's
  start) to complete its header, then closes the connection (slowloris);
* answers protocol-level errors (bad request line, oversized header) as
  ``application/problem+json`` with ``Connection: close``.

Request bodies are bounded in size and time by :class:`service.api.limits.BodyLimitMiddleware`,
idle keep-alive connections by uvicorn's ``timeout_keep_alive``.
"""

from __future__ import annotations

import asyncio
import json
import sys
import time
from typing import Any

import h11
from uvicorn.protocols.http.h11_impl import H11Protocol

from service.api.logs import get_logger

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
    header_timeout: float = 10.0
    refusals = _Refusals()

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self._header_timer: asyncio.TimerHandle | None = None
        if len(self.connections) > self.max_connections:
            self.refusals.add(len(self.connections))
            transport.abort()
            return
        self._arm_header_timer()

    def _arm_header_timer(self) -> None:
        if self._header_timer is None:
            self._header_timer = self.loop.call_later(self.header_timeout, self._header_expired)

    def _disarm_header_timer(self) -> None:
        if self._header_timer is not None:
            self._header_timer.cancel()
            self._header_timer = None

    def data_received(self, data: bytes) -> None:
        if self.conn.their_state is h11.IDLE:
            self._arm_header_timer()
        super().data_received(data)
        if self.conn.their_state is not h11.IDLE:
            self._disarm_header_timer()

    def on_response_complete(self) -> None:
        super().on_response_complete()
        self._disarm_header_timer()  # idle from here on: uvicorn's keep-alive timeout applies

    def _header_expired(self) -> None:
        self._header_timer = None
        if self.conn.their_state is h11.IDLE and not self.transport.is_closing():
            self.transport.close()

    def connection_lost(self, exc: Exception | None) -> None:
        self._disarm_header_timer()
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


def guarded_protocol(max_connections: int, header_timeout: float) -> type[Any]:
    """An :class:`GuardedH11Protocol` subclass with these bounds (for ``uvicorn.Config``)."""
    return type(
        "GeosmoothH11Protocol",
        (GuardedH11Protocol,),
        {
            "max_connections": max_connections,
            "header_timeout": header_timeout,
            "refusals": _Refusals(),
        },
    )
