"""A real uvicorn server on loopback running a test's own Starlette app, in a thread.

For answers the geosmooth service gives rarely or not yet on this branch (401, 429 with
``Retry-After``, a 503 then a success, an events stream cut in the middle, a slow reader), so the
client is exercised over real HTTP. Everything else is tested against the real service.
"""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Sequence
from typing import Any

import uvicorn
from starlette.applications import Starlette
from starlette.routing import BaseRoute


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


class ScriptedServer:
    """``with ScriptedServer(routes) as server: ... server.url ... server.requests``.

    Attributes
    ----------
    requests : list of dict
        ``{"method", "path", "headers"}`` of every request, in order (the routes append).
    """

    def __init__(self, routes: Sequence[BaseRoute]) -> None:
        self.port = _free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.requests: list[dict[str, Any]] = []
        app = Starlette(routes=list(routes))

        async def recorded(scope: Any, receive: Any, send: Any) -> None:
            if scope["type"] == "http":
                headers = {k.decode("latin-1"): v.decode("latin-1") for k, v in scope["headers"]}
                self.requests.append(
                    {"method": scope["method"], "path": scope["path"], "headers": headers}
                )
            await app(scope, receive, send)

        config = uvicorn.Config(recorded, host="127.0.0.1", port=self.port, log_level="warning")
        self._server = uvicorn.Server(config)
        self._thread = threading.Thread(target=self._server.run, daemon=True)

    def __enter__(self) -> ScriptedServer:
        self._thread.start()
        deadline = time.monotonic() + 10
        while not self._server.started:
            if time.monotonic() > deadline or not self._thread.is_alive():
                raise RuntimeError("scripted server did not start")
            time.sleep(0.01)
        return self

    def __exit__(self, *exc: object) -> None:
        self._server.should_exit = True
        self._thread.join(10)

    def paths(self, method: str | None = None) -> list[str]:
        """Paths requested (of one method)."""
        return [r["path"] for r in self.requests if method in (None, r["method"])]
