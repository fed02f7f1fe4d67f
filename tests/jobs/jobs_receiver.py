"""A webhook receiver on 127.0.0.1 for the tests: records every POST, answers scripted statuses."""

from __future__ import annotations

import http.server
import re
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tests.jobs.jobs_helpers import REPO


@dataclass
class Delivery:
    """One POST the receiver got."""

    path: str
    headers: dict[str, str]
    body: bytes


@dataclass
class Receiver:
    """``with Receiver([500, 200]) as r: ...``: answers 500, then 200 (the last status repeats)."""

    statuses: list[int] = field(default_factory=lambda: [200])
    deliveries: list[Delivery] = field(default_factory=list)
    server: http.server.ThreadingHTTPServer | None = None

    def __enter__(self) -> Receiver:
        owner = self

        class Handler(http.server.BaseHTTPRequestHandler):
            def do_POST(self) -> None:
                body = self.rfile.read(int(self.headers.get("Content-Length", 0)))
                owner.deliveries.append(Delivery(self.path, dict(self.headers), body))
                status = owner.statuses[min(len(owner.deliveries), len(owner.statuses)) - 1]
                self.send_response(status)
                self.send_header("Content-Length", "0")
                self.end_headers()

            def log_message(self, *args: Any) -> None:
                return None

        self.server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        threading.Thread(target=self.server.serve_forever, daemon=True).start()
        return self

    def __exit__(self, *exc: object) -> None:
        assert self.server is not None
        self.server.shutdown()
        self.server.server_close()

    def url(self, path: str = "/hook") -> str:
        assert self.server is not None
        return f"http://127.0.0.1:{self.server.server_address[1]}{path}"


def documented_verifier() -> Any:
    """The ``verify`` function of docs/http-api.md's webhook section (executed as documented)."""
    text = (Path(REPO) / "docs" / "http-api.md").read_text()
    match = re.search(r"<!-- webhook-verify -->\s*```python\n(.*?)```", text, re.S)
    assert match, "docs/http-api.md has no webhook verification snippet"
    namespace: dict[str, Any] = {}
    exec(compile(match.group(1), "docs/http-api.md#webhook-verify", "exec"), namespace)
    return namespace["verify"]
