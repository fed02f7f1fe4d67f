"""Request body size limit, enforced while the body streams in.

A request whose ``Content-Length`` exceeds the limit is answered 413 before the application
sees it. Otherwise (chunked uploads, lying headers) the bytes are counted as they are received
and the request fails with 413 as soon as the count passes the limit, so no more than the limit
is ever buffered or spooled.
"""

from __future__ import annotations

from starlette.datastructures import Headers
from starlette.exceptions import HTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from service.api.problems import ApiProblem, problem_response

__all__ = ["BodySizeLimitMiddleware", "PayloadTooLarge"]


class PayloadTooLarge(HTTPException):
    """The request body passed the limit while it was being read."""

    def __init__(self, limit: int) -> None:
        super().__init__(413, f"request body exceeds the limit of {limit} bytes")
        self.limit = limit


def _too_large(limit: int, size: int | None = None) -> ApiProblem:
    detail = f"request body exceeds the limit of {limit} bytes"
    if size is not None:
        detail = f"request body of {size} bytes exceeds the limit of {limit} bytes"
    return ApiProblem(413, detail, code="payload-too-large", max_upload_bytes=limit)


class BodySizeLimitMiddleware:
    """Pure ASGI middleware limiting request bodies to ``max_bytes``.

    Parameters
    ----------
    app : ASGI app
        The wrapped application.
    max_bytes : int
        Largest body accepted, in bytes.
    """

    def __init__(self, app: ASGIApp, max_bytes: int) -> None:
        self.app = app
        self.max_bytes = max_bytes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        limit = self.max_bytes
        declared = Headers(scope=scope).get("content-length")
        if declared is not None and declared.isdigit() and int(declared) > limit:
            response = problem_response(_too_large(limit, int(declared)), scope.get("path"))
            await response(scope, receive, send)
            return

        received = 0
        started = False

        async def counting_receive() -> Message:
            nonlocal received
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > limit:
                    raise PayloadTooLarge(limit)
            return message

        async def tracking_send(message: Message) -> None:
            nonlocal started
            if message["type"] == "http.response.start":
                started = True
            await send(message)

        try:
            await self.app(scope, counting_receive, tracking_send)
        except PayloadTooLarge:
            # Normally FastAPI's handlers answer it; this catches reads outside a route.
            if started:
                raise
            response = problem_response(_too_large(limit), scope.get("path"))
            await response(scope, receive, send)
