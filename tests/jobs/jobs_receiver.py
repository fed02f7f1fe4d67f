"""A webhook receiver on 127.0.0.1 for the tests: records every POST, answers scripted statuses."""

from __future__ import annotations

import http.server
import itertools
import re
import select
import socket
import socketserver
import threading
import time
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


class _Served:
    """A server on 127.0.0.1 run by a daemon thread, shut down on ``__exit__``."""

    server: socketserver.BaseServer | None

    def _serve(self, server: socketserver.BaseServer) -> None:
        self.server = server
        threading.Thread(target=server.serve_forever, daemon=True).start()

    def __exit__(self, *exc: object) -> None:
        assert self.server is not None
        self.server.shutdown()
        self.server.server_close()

    def url(self, path: str = "/hook") -> str:
        assert self.server is not None
        return f"http://127.0.0.1:{self.server.server_address[1]}{path}"  # type: ignore[index]


class _Threads(socketserver.ThreadingTCPServer):
    daemon_threads = True


@dataclass
class Receiver(_Served):
    """``with Receiver([500, 200]) as r: ...``: answers 500, then 200 (the last status repeats)."""

    statuses: list[int] = field(default_factory=lambda: [200])
    deliveries: list[Delivery] = field(default_factory=list)
    server: socketserver.BaseServer | None = None

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

        self._serve(http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler))
        return self


def documented_verifier() -> Any:
    """The ``verify`` function of docs/http-api.md's webhook section (executed as documented)."""
    text = (Path(REPO) / "docs" / "http-api.md").read_text()
    match = re.search(r"<!-- webhook-verify -->\s*```python\n(.*?)```", text, re.S)
    assert match, "docs/http-api.md has no webhook verification snippet"
    namespace: dict[str, Any] = {}
    exec(compile(match.group(1), "docs/http-api.md#webhook-verify", "exec"), namespace)
    return namespace["verify"]


@dataclass
class HostileReceiver(_Served):
    """A receiver on 127.0.0.1 that reads the POST and then misbehaves, one ``mode`` of:

    ``endless``: 200 and a body without end (at most ``limit`` bytes, then it closes);
    ``huge``: 200 with ``Content-Length: 1 GiB`` and that body (at most ``limit`` bytes sent);
    ``trickle``: a valid 200 answer sent one byte every ``pace`` seconds, its body never ending;
    ``silent``: no answer at all (until ``limit`` bytes' worth of ``pace`` waits pass).

    ``sent`` counts the bytes it wrote, ``cut`` whether the client closed the connection first.
    """

    mode: str
    limit: int = 64 << 20
    pace: float = 0.05
    sent: int = 0
    cut: threading.Event = field(default_factory=threading.Event)
    done: threading.Event = field(default_factory=threading.Event)
    server: socketserver.BaseServer | None = None

    def _answer(self, sock: socket.socket) -> None:
        head = b"HTTP/1.1 200 OK\r\nContent-Type: text/plain\r\n"
        if self.mode == "endless":
            self._send(sock, head + b"Connection: close\r\n\r\n", b"x" * 65536)
        elif self.mode == "huge":
            self._send(sock, head + b"Content-Length: 1073741824\r\n\r\n", b"x" * 65536)
        elif self.mode == "trickle":
            answer = head + b"Transfer-Encoding: chunked\r\n\r\n"
            chunks = itertools.chain([answer], itertools.repeat(b"1\r\nx\r\n"))
            for byte in itertools.islice(itertools.chain.from_iterable(chunks), self.limit):
                self._send(sock, b"", bytes([byte]))
                time.sleep(self.pace)
        else:
            for _ in range(self.limit):
                time.sleep(self.pace)
                if _closed(sock):
                    self.cut.set()
                    return

    def _send(self, sock: socket.socket, first: bytes, block: bytes) -> None:
        if first:
            sock.sendall(first)
        while self.sent < self.limit:
            sock.sendall(block)
            self.sent += len(block)
            if self.mode == "trickle":
                return

    def __enter__(self) -> HostileReceiver:
        owner = self

        class Handler(socketserver.BaseRequestHandler):
            def handle(self) -> None:
                sock: socket.socket = self.request
                data = b""
                while b"\r\n\r\n" not in data:
                    data += sock.recv(65536)
                head, _, rest = data.partition(b"\r\n\r\n")
                length = int(re.search(rb"(?i)content-length: *(\d+)", head)[1])  # type: ignore[index]
                while len(rest) < length:
                    rest += sock.recv(65536)
                try:
                    owner._answer(sock)
                except OSError:  # BrokenPipe, ConnectionReset: the client hung up
                    owner.cut.set()
                finally:
                    owner.done.set()

        self._serve(_Threads(("127.0.0.1", 0), Handler))
        return self


def _closed(sock: socket.socket) -> bool:
    """Whether the peer closed ``sock`` (readable with nothing to read)."""
    ready, _, _ = select.select([sock], [], [], 0)
    return bool(ready) and sock.recv(1, socket.MSG_PEEK) == b""
