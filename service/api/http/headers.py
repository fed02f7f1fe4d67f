"""Headers on every response (the outermost middleware): security, and ``Retry-After``.

* ``X-Content-Type-Options: nosniff`` on every response, so a browser never runs a downloaded
  result or an error body as a script or a page.
* Every HTML response (the page at ``/``, ``/static/*.html``, ``/docs``, ``/redoc``) carries the
  pages' Content-Security-Policy (:data:`CSP`, with ``frame-ancestors 'none'``: no other site can
  frame the page and click through it) and ``X-Frame-Options: DENY`` for older browsers; a route
  that sets its own policy keeps it.
* Every 503 and 507 carries ``Retry-After`` (5 s and 30 s unless the answer set its own): a
  client (or the Python client's retry loop) knows the condition is temporary.
"""

from __future__ import annotations

from starlette.datastructures import MutableHeaders
from starlette.types import ASGIApp, Message, Receive, Scope, Send

__all__ = ["CSP", "SecurityHeaders"]

#: ``Retry-After`` (seconds) of a 503 (a store or broker that cannot be reached, e.g. Redis
#: down) or 507 (out of space) answer that did not set its own.
_RETRY_AFTER = {503: 5, 507: 30}

#: Content-Security-Policy of the HTML pages: the browser itself refuses every other origin.
#: (ReDoc 2.5.4 shows its logo from its CDN as an <img>; this policy is what stops that request,
#: and the bundle then hides the image.) Inline scripts: FastAPI's docs pages and the page's
#: import map; inline styles: Swagger UI, ReDoc and three.js set them.
CSP = "; ".join(
    [
        "default-src 'self'",
        "script-src 'self' 'unsafe-inline'",
        "style-src 'self' 'unsafe-inline'",
        "img-src 'self' data: blob:",
        "font-src 'self' data:",
        "connect-src 'self'",
        "worker-src 'self' blob:",
        "frame-ancestors 'none'",
        "base-uri 'self'",
        "form-action 'self'",
    ]
)


class SecurityHeaders:
    """Pure ASGI middleware adding the headers of the module docstring."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = MutableHeaders(scope=message)
                headers["X-Content-Type-Options"] = "nosniff"
                wait = _RETRY_AFTER.get(message["status"])
                if wait is not None and "retry-after" not in headers:
                    headers["Retry-After"] = str(wait)
                if headers.get("content-type", "").startswith("text/html"):
                    if "content-security-policy" not in headers:
                        headers["Content-Security-Policy"] = CSP
                    headers["X-Frame-Options"] = "DENY"
            await send(message)

        await self.app(scope, receive, send_with_headers)
