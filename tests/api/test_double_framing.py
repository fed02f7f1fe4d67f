"""Issue 42 finding 9: a request with both ``Content-Length`` and ``Transfer-Encoding`` kept its
connection open; RFC 9112 section 6.1 says the server must close it after responding."""

from __future__ import annotations

import socket

from tests.api.api_helpers import LiveServer

PLAIN = b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n"


def _answer(sock: socket.socket) -> bytes:
    """One answer's head (b"": the connection was closed instead)."""
    data = b""
    while b"\r\n\r\n" not in data:
        try:
            chunk = sock.recv(65536)
        except ConnectionResetError:
            return b""
        if not chunk:
            return b""
        data += chunk
    head, _, body = data.partition(b"\r\n\r\n")
    length = int(next(ln.split(b":")[1] for ln in head.split(b"\r\n")
                      if ln.lower().startswith(b"content-length")))  # fmt: skip
    while len(body) < length:
        body += sock.recv(65536)
    return head


def _two_requests(server: LiveServer, first: bytes) -> tuple[bytes, bytes]:
    """The heads of the answers to ``first`` and then to a plain request on the same
    connection (b"" for the second: the server closed the connection after the first)."""
    with socket.create_connection(("127.0.0.1", server.port), timeout=60) as sock:
        sock.sendall(first)
        head = _answer(sock)
        try:
            sock.sendall(PLAIN)
        except (BrokenPipeError, ConnectionResetError):
            return head, b""
        return head, _answer(sock)


def test_both_framings_close_the_connection(server: LiveServer) -> None:
    both = (b"POST /v1/info HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: 5\r\n"
            b"Transfer-Encoding: chunked\r\nContent-Type: application/json\r\n\r\n"
            b"0\r\n\r\n")  # fmt: skip
    head, then = _two_requests(server, both)
    assert head.startswith(b"HTTP/1.1 4"), head  # answered (no file: refused)
    assert then == b"", "the connection stayed open after a doubly framed request"
    head, then = _two_requests(server, PLAIN)  # an ordinary request keeps its connection
    assert head.startswith(b"HTTP/1.1 200") and then.startswith(b"HTTP/1.1 200")
