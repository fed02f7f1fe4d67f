"""Request body bounds, enforced while the body streams in.

* Size: a request whose ``Content-Length`` exceeds the key's ``max_upload_bytes`` is answered
  413 before the application sees it. Otherwise (chunked uploads, lying headers) the bytes are
  counted as they are received and the request fails with 413 as soon as the count passes the
  limit, so no more than the limit is ever spooled.
* Stall: a body that stalls (no byte for ``timeout_body_read`` seconds) is answered 408.
* Pace: a body must keep up with ``body_min_rate`` bytes/s averaged over ``body_rate_window``
  (:class:`BodyPace`): a client trickling a byte now and then is answered 408 within
  ``body_rate_window`` + :data:`GRACE_SECONDS`, and a body of ``S`` bytes gets at most
  ``body_rate_window + S / body_min_rate`` seconds in all. Only time spent waiting for the
  client counts (not the time the server spends writing the spool or doing other work), and a
  server that was too busy to read gets :data:`GRACE_SECONDS` to read what is already there, so
  load never turns a legal upload into a 408.

Every 408 is ``body-timeout`` naming its limit; 408 and 413 close the connection
(``Connection: close``) instead of draining a slow client. The route reading the body removes
its spool file when the read fails (:mod:`service.api.intake.uploads`).
"""

from __future__ import annotations

import math
import time
from typing import Any

import anyio
from starlette.datastructures import Headers
from starlette.exceptions import HTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from service.api.errors import ApiProblem
from service.api.problems import problem_response

__all__ = ["GRACE_SECONDS", "BodyLimitMiddleware", "BodyPace", "BodyTimeout", "PayloadTooLarge"]

_CLOSE = {"Connection": "close"}

#: Extra seconds a read may wait once a body's credit is spent: what a client already sent is
#: read before the body is refused, however late a busy server gets to it.
GRACE_SECONDS = 1.0


class PayloadTooLarge(HTTPException):
    """The request body passed the limit while it was being read."""

    def __init__(self, limit: int) -> None:
        super().__init__(413, f"request body exceeds the limit of {limit} bytes", headers=_CLOSE)
        self.limit = limit


class BodyTimeout(ApiProblem):
    """408 ``body-timeout``: the request body stalled or fell behind the minimum rate; the
    problem names the limit (``limit`` and its value)."""

    def __init__(self, detail: str, limit: str, **values: Any) -> None:
        super().__init__(408, detail, code="body-timeout", headers=_CLOSE, limit=limit, **values)

    @classmethod
    def stalled(cls, seconds: float) -> BodyTimeout:
        return cls(
            f"no request body received for {seconds:g} s (timeout_body_read); closing",
            "timeout_body_read",
            timeout_body_read=seconds,
        )

    @classmethod
    def too_slow(cls, pace: BodyPace) -> BodyTimeout:
        return cls(
            f"the request body arrived slower than {pace.min_rate} bytes/s over "
            f"{pace.window:g} s (body_min_rate, body_rate_window); closing",
            "body_min_rate",
            body_min_rate=pace.min_rate,
            body_rate_window=pace.window,
        )


class BodyPace:
    """The minimum rate of one request body, as a credit of bytes.

    The credit starts at ``min_rate * window``, is spent at ``min_rate`` per second spent
    waiting for the body and refilled by every byte received, never above its start. A body
    whose credit is spent has fallen behind the minimum rate over the last ``window`` seconds
    (a client cannot bank more than ``window`` seconds of credit by sending fast first).
    ``min_rate`` 0: no bound.
    """

    def __init__(self, min_rate: int, window: float) -> None:
        self.min_rate = min_rate
        self.window = window
        self.cap = min_rate * window
        self.credit = self.cap

    def budget(self) -> float:
        """Seconds the next read may wait before the credit is spent."""
        if self.min_rate <= 0:
            return math.inf
        return max(self.credit, 0.0) / self.min_rate

    def record(self, waited: float, size: int) -> bool:
        """Account a read of ``size`` bytes after ``waited`` seconds; False: fallen behind."""
        if self.min_rate <= 0:
            return True
        self.credit = min(self.cap, self.credit - self.min_rate * waited + size)
        return self.credit > 0


def _too_large(limit: int, size: int | None = None) -> ApiProblem:
    detail = f"request body exceeds the limit of {limit} bytes"
    if size is not None:
        detail = f"request body of {size} bytes exceeds the limit of {limit} bytes"
    return ApiProblem(413, detail, code="payload-too-large", max_upload_bytes=limit, headers=_CLOSE)


class _BoundedBody:
    """The ``receive`` of one request, bounded in size, stall and pace."""

    def __init__(self, receive: Receive, limit: int, read_timeout: float, pace: BodyPace) -> None:
        self._receive = receive
        self.limit = limit
        self.read_timeout = read_timeout
        self.pace = pace
        self.received = 0
        self.done = False

    async def __call__(self) -> Message:
        if self.done:  # waiting for a disconnect: not a body read
            return await self._receive()
        budget = self.pace.budget()
        started = time.monotonic()
        message = await self._read(min(self.read_timeout, budget))
        if message is None:  # a late server may not have read what was sent: a last chance
            message = await self._read(GRACE_SECONDS)
            if message is None:
                if budget < self.read_timeout:
                    raise BodyTimeout.too_slow(self.pace)
                raise BodyTimeout.stalled(self.read_timeout)
        if message["type"] != "http.request":
            self.done = True
            return message
        size = len(message.get("body", b""))
        self.received += size
        self.done = not message.get("more_body", False)
        if self.received > self.limit:
            raise PayloadTooLarge(self.limit)
        if not self.pace.record(time.monotonic() - started, size) and not self.done:
            raise BodyTimeout.too_slow(self.pace)
        return message

    async def _read(self, seconds: float) -> Message | None:
        """The next message, or None after ``seconds``."""
        with anyio.move_on_after(seconds):
            return await self._receive()
        return None


class BodyLimitMiddleware:
    """Pure ASGI middleware bounding request bodies in size, stall and pace.

    Parameters
    ----------
    app : ASGI app
        The wrapped application.
    max_bytes : int
        Largest body when the request has no principal with its own limit.
    read_timeout : float
        Seconds without body bytes before 408.
    min_rate : int
        Slowest body accepted, bytes/s averaged over ``rate_window`` (:class:`BodyPace`);
        0: no bound.
    rate_window : float
        Seconds ``min_rate`` is averaged over.
    """

    def __init__(
        self,
        app: ASGIApp,
        max_bytes: int,
        read_timeout: float,
        min_rate: int = 0,
        rate_window: float = 30.0,
    ) -> None:
        self.app = app
        self.max_bytes = max_bytes
        self.read_timeout = read_timeout
        self.min_rate = min_rate
        self.rate_window = rate_window

    def _limit(self, scope: Scope) -> int:
        principal = scope.get("state", {}).get("principal")
        return int(principal.limits.max_upload_bytes) if principal is not None else self.max_bytes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        limit = self._limit(scope)
        declared = Headers(scope=scope).get("content-length")
        if declared is not None and declared.isdigit() and int(declared) > limit:
            response = problem_response(_too_large(limit, int(declared)), scope.get("path"))
            await response(scope, receive, send)
            return
        pace = BodyPace(self.min_rate, self.rate_window)
        bounded = _BoundedBody(receive, limit, self.read_timeout, pace)
        started = False

        async def tracking_send(message: Message) -> None:
            nonlocal started
            if message["type"] == "http.response.start":
                started = True
            await send(message)

        try:
            await self.app(scope, bounded, tracking_send)
        except (PayloadTooLarge, BodyTimeout) as exc:
            # Normally the app's handlers answer these; this catches reads outside a route.
            if started:
                raise
            problem = _too_large(limit) if isinstance(exc, PayloadTooLarge) else exc
            await problem_response(problem, scope.get("path"))(scope, receive, send)
