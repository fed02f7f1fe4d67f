"""The outermost middleware: request id, one log line per request, and the last-resort answer.

* ``X-Request-ID``: taken from the request when it is a sane token (<= 128 characters of
  ``[A-Za-z0-9._:-]``), generated otherwise; echoed on every response and bound to every log
  line of the request (``request_id``).
* One ``request`` log line per request: method, path, status, duration_ms, client, tenant.
* Any exception that escapes the app is answered here as problem details (typed errors with
  their own status, anything else 500 without internals, logged with its traceback) *and the
  connection stays usable*: the exception is not re-raised to the server, which would close a
  kept-alive connection silently.
"""

from __future__ import annotations

import errno
import re
import time
import uuid
from typing import Any

import structlog
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from service.api.http.logs import get_logger
from service.api.problems import problem_from_exception, problem_response
from service.jobs.errors import StorageFull

__all__ = ["REQUEST_ID_HEADER", "RequestContextMiddleware"]

REQUEST_ID_HEADER = "X-Request-ID"
_SANE_ID = re.compile(r"[A-Za-z0-9._:-]{1,128}")
log = get_logger("geosmooth.api")


def _incoming_id(scope: Scope) -> str:
    for name, value in scope.get("headers", ()):
        if name == b"x-request-id":
            text = value.decode("latin-1").strip()
            if _SANE_ID.fullmatch(text):
                return text
            break
    return uuid.uuid4().hex


class RequestContextMiddleware:
    """Pure ASGI middleware (see the module docstring)."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        request_id = _incoming_id(scope)
        scope.setdefault("state", {})["request_id"] = request_id
        structlog.contextvars.clear_contextvars()
        structlog.contextvars.bind_contextvars(request_id=request_id)
        start = time.perf_counter()
        status: dict[str, Any] = {"code": None, "started": False}

        async def send_with_id(message: Message) -> None:
            if message["type"] == "http.response.start":
                status["code"], status["started"] = message["status"], True
                headers = list(message.get("headers", []))
                headers.append((b"x-request-id", request_id.encode("latin-1")))
                message = {**message, "headers": headers}
            await send(message)

        try:
            await self.app(scope, receive, send_with_id)
        except Exception as exc:
            if status["started"]:
                log.exception("request.error", method=scope["method"], path=scope["path"])
                raise  # half a response is out: the server must close the connection
            problem = problem_from_exception(_disk_full(exc) or exc)
            if problem.status >= 500 and problem.status != 507:
                log.error("request.error", exc_info=exc, method=scope["method"], path=scope["path"])
                problem.extensions["request_id"] = request_id
            await problem_response(problem, scope.get("path"))(scope, receive, send_with_id)
        finally:
            principal = scope.get("state", {}).get("principal")
            log.info(
                "request",
                method=scope["method"],
                path=scope["path"],
                status=status["code"],
                duration_ms=round(1000 * (time.perf_counter() - start), 2),
                client=(scope.get("client") or ("-",))[0],
                tenant=getattr(principal, "tenant", None),
            )
            structlog.contextvars.clear_contextvars()


def _disk_full(exc: BaseException) -> BaseException | None:
    """ENOSPC/EDQUOT anywhere in a request: the typed 507 ``storage-full`` (never a 500)."""
    if isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EDQUOT):
        return StorageFull("the server is out of disk space")
    return None
