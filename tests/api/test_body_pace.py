"""Issue 34 item 6 on a live server: an upload body must keep up with ``body_min_rate`` bytes/s
averaged over ``body_rate_window`` seconds. A client trickling a byte now and then gets 408
``body-timeout`` (naming the limit) within the window plus the grace second, and its spool file is
removed; a fast upload, a slow one above the floor and one a stopped (busy) server could not read
for longer than the window are all accepted.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from tests.api.api_helpers import LiveServer, encode, noisy_plane_cloud

WINDOW = 3.0  # body_rate_window of these servers
MIN_RATE = 1000  # body_min_rate (bytes/s)
PACE_ENV = {
    "GEOSMOOTH_BODY_MIN_RATE": str(MIN_RATE),
    "GEOSMOOTH_BODY_RATE_WINDOW": str(WINDOW),
    "GEOSMOOTH_TIMEOUT_BODY_READ": "30",  # the stall bound stays far away: only the pace acts
}
BOUNDARY = "pace-boundary-7f3a"


def _multipart(payload: bytes) -> tuple[bytes, bytes, bytes]:
    """Request head, the file part's own head and the closing tail of a one-file upload."""
    part = (
        f'--{BOUNDARY}\r\nContent-Disposition: form-data; name="params"\r\n\r\n'
        '{"lam": 1.0}\r\n'
        f'--{BOUNDARY}\r\nContent-Disposition: form-data; name="file"; filename="c.xyz"\r\n'
        "Content-Type: text/plain\r\n\r\n"
    ).encode()
    tail = f"\r\n--{BOUNDARY}--\r\n".encode()
    head = (
        "POST /v1/jobs HTTP/1.1\r\nHost: 127.0.0.1\r\n"
        f"Content-Type: multipart/form-data; boundary={BOUNDARY}\r\n"
        f"Content-Length: {len(part) + len(payload) + len(tail)}\r\n\r\n"
    ).encode()
    return head, part, tail


def _answer(sock: socket.socket) -> bytes:
    """Everything the server sends until it closes (or 30 s of silence)."""
    sock.settimeout(30)
    data = b""
    try:
        while chunk := sock.recv(65536):
            data += chunk
    except (TimeoutError, ConnectionResetError):
        pass
    return data


def _problem(answer: bytes) -> tuple[int, dict[str, object]]:
    head, _, body = answer.partition(b"\r\n\r\n")
    status = int(head.split(b" ", 2)[1])
    if b"transfer-encoding: chunked" in head.lower():  # not expected, but decode if so
        size, _, rest = body.partition(b"\r\n")
        body = rest[: int(size, 16)]
    return status, json.loads(body)


def _spooled(live: LiveServer) -> list[Path]:
    return list((live.data_dir / "spool").glob("upload-*"))


def _wait(cond: Callable[[], bool], timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(0.05)
    return cond()


def _send_paced(sock: socket.socket, data: bytes, rate: float, chunk: int = 250) -> None:
    """``data`` at about ``rate`` bytes/s."""
    for i in range(0, len(data), chunk):
        sock.sendall(data[i : i + chunk])
        time.sleep(chunk / rate)


@pytest.fixture
def paced(make_server: Callable[..., LiveServer]) -> LiveServer:
    return make_server(workers=1, **PACE_ENV)


def test_a_trickling_body_gets_408_within_the_window_and_its_spool_is_removed(
    paced: LiveServer,
) -> None:
    head, part, _ = _multipart(b"0" * 100_000)
    with socket.create_connection(("127.0.0.1", paced.port), timeout=30) as sock:
        sock.sendall(head + part + b"0.0 0.0 0.0\n")
        assert _wait(lambda: bool(_spooled(paced)), 30), paced.log()  # the file part is spooled
        start = time.monotonic()
        sock.settimeout(0.5)
        answer = b""
        while time.monotonic() - start < 60 and not answer:
            try:
                sock.sendall(b"1")  # a byte every half second: never a stall, far below the rate
                answer = sock.recv(65536)
            except TimeoutError:
                continue
            except OSError:
                break
        held = time.monotonic() - start
        answer += _answer(sock)
    status, problem = _problem(answer)
    assert status == 408, answer[:300]
    assert problem["code"] == "body-timeout" and problem["limit"] == "body_min_rate", problem
    assert problem["body_min_rate"] == MIN_RATE and problem["body_rate_window"] == WINDOW
    assert b"connection: close" in answer.lower()
    # closed once the window's credit is spent (plus the grace second), not held: the bound
    # below leaves room for a loaded machine, the trickle alone would take 28 hours
    assert WINDOW * 0.5 <= held < WINDOW + 1.0 + 10.0, held
    assert _wait(lambda: not _spooled(paced), 10), _spooled(paced)


def test_fast_and_slow_but_legal_uploads_are_accepted(paced: LiveServer) -> None:
    with paced.client() as c:
        files = {"file": ("big.xyz", encode("xyz", noisy_plane_cloud(20_000, seed=3), None))}
        r = c.post("/v1/jobs", files=files, data={"params": json.dumps({"lam": 1.0})})
        assert r.status_code == 202, r.text
    payload = encode("xyz", noisy_plane_cloud(300, seed=4), None)
    head, part, tail = _multipart(payload)
    assert len(payload) / (2 * MIN_RATE) > WINDOW  # the body takes longer than the window
    with socket.create_connection(("127.0.0.1", paced.port), timeout=30) as sock:
        sock.sendall(head + part)
        _send_paced(sock, payload, rate=2 * MIN_RATE)  # twice the floor
        sock.sendall(tail)
        answer = sock.recv(65536)
    assert answer.startswith(b"HTTP/1.1 202"), answer[:300]


def test_a_server_too_busy_to_read_does_not_refuse_a_legal_body(paced: LiveServer) -> None:
    """The server is stopped (SIGSTOP) for twice the window while the client keeps sending at
    twice the floor: the time it could not read is the server's, what the client sent is
    credited when it resumes, and the upload is accepted."""
    assert paced.proc is not None
    payload = encode("xyz", noisy_plane_cloud(300, seed=5), None)
    head, part, tail = _multipart(payload)
    with socket.create_connection(("127.0.0.1", paced.port), timeout=30) as sock:
        sock.sendall(head + part)
        assert _wait(lambda: bool(_spooled(paced)), 30), paced.log()
        os.kill(paced.proc.pid, signal.SIGSTOP)
        try:
            _send_paced(sock, payload, rate=2 * MIN_RATE)  # about 2 x WINDOW seconds
        finally:
            os.kill(paced.proc.pid, signal.SIGCONT)
        sock.sendall(tail)
        answer = sock.recv(65536)
    assert answer.startswith(b"HTTP/1.1 202"), answer[:300]


def test_body_pace_credit() -> None:
    """The credit: spent while waiting, refilled by bytes, never above ``min_rate * window``."""
    from service.api.http.limits import BodyPace

    pace = BodyPace(1000, 3.0)
    assert pace.budget() == 3.0
    assert pace.record(1.0, 0) and pace.budget() == 2.0
    assert pace.record(0.5, 10**6) and pace.budget() == 3.0  # capped: no banking ahead
    assert not pace.record(3.5, 100)  # 3.5 s for 100 bytes: behind the floor
    off = BodyPace(0, 3.0)
    assert off.budget() == float("inf") and off.record(1e6, 0)
