"""Request body bounds, enforced while the body streams in.

* Size: a request whose ``Content-Length`` exceeds the key's ``max_upload_bytes`` is answered
  413 before the application sees it. Otherwise (chunked uploads, lying headers) the bytes are
  counted as they are received and the request fails with 413 as soon as the count passes the
  limit, so no more than the limit is ever spooled.
* Time: a body that stalls (no byte for ``timeout_body_read`` seconds) is answered 408; both
  answers close the connection (``Connection: close``) instead of draining a slow client.
"""

from __future__ import annotations

import anyio
from starlette.datastructures import Headers
from starlette.exceptions import HTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from service.api.errors import ApiProblem
from service.api.problems import problem_response

__all__ = ["BodyLimitMiddleware", "BodyTimeout", "PayloadTooLarge"]

_CLOSE = {"Connection": "close"}


class PayloadTooLarge(HTTPException):
    """The request body passed the limit while it was being read."""

    def __init__(self, limit: int) -> None:
        super().__init__(413, f"request body exceeds the limit of {limit} bytes", headers=_CLOSE)
        self.limit = limit


class BodyTimeout(HTTPException):
    """No byte of the request body arrived for too long."""

    def __init__(self, seconds: float) -> None:
        super().__init__(
            408, f"no request body received for {seconds:g} s; closing", headers=_CLOSE
        )


def _too_large(limit: int, size: int | None = None) -> ApiProblem:
    detail = f"request body exceeds the limit of {limit} bytes"
    if size is not None:
        detail = f"request body of {size} bytes exceeds the limit of {limit} bytes"
    return ApiProblem(413, detail, code="payload-too-large", max_upload_bytes=limit, headers=_CLOSE)


class BodyLimitMiddleware:
    """Pure ASGI middleware bounding request bodies in size and in time.

    Parameters
    ----------
    app : ASGI app
        The wrapped application.
    max_bytes : int
        Largest body when the request has no principal with its own limit.
    read_timeout : float
        Seconds without body bytes before 408.
    """

    def __init__(self, app: ASGIApp, max_bytes: int, read_timeout: float) -> None:
        self.app = app
        self.max_bytes = max_bytes
        self.read_timeout = read_timeout

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
        received = 0
        body_done = False
        started = False

        async def bounded_receive() -> Message:
            nonlocal received, body_done
            if body_done:  # waiting for a disconnect: not a body read
                return await receive()
            with anyio.move_on_after(self.read_timeout) as scope_:
                message = await receive()
            if scope_.cancelled_caught:
                raise BodyTimeout(self.read_timeout)
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                body_done = not message.get("more_body", False)
                if received > limit:
                    raise PayloadTooLarge(limit)
            else:
                body_done = True
            return message

        async def tracking_send(message: Message) -> None:
            nonlocal started
            if message["type"] == "http.response.start":
                started = True
            await send(message)

        try:
            await self.app(scope, bounded_receive, tracking_send)
        except (PayloadTooLarge, BodyTimeout) as exc:
            # Normally the app's handlers answer these; this catches reads outside a route.
            if started:
                raise
            problem = (
                _too_large(limit)
                if isinstance(exc, PayloadTooLarge)
                else ApiProblem(408, str(exc.detail), code="body-timeout", headers=_CLOSE)
            )
            await problem_response(problem, scope.get("path"))(scope, receive, send)
