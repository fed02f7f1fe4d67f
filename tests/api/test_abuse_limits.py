"""Issue 24 item 7 on live servers: wrong API keys are rate limited per client address (429 +
``Retry-After``, then every ``/v1`` request of that address, so the answers are no oracle); event
streams over a key's bound and connections over a client's bound get an HTTP answer (429 +
``Retry-After``) instead of a silent close."""

from __future__ import annotations

import json
import socket
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack

import httpx

from tests.api.api_helpers import KEYS, LiveServer, encode, noisy_plane_cloud

# About 20-30 s of solving on a quiet machine (see test_cancel_restart): keeps a second job queued.
SLOW_PARAMS = {"tau": 1.0, "tolerance": 1e-9, "neighborhood": "knn", "k": 64}


def _from(live: LiveServer, source: str, **headers: str) -> httpx.Client:
    """A client whose connections come from the loopback address ``source``."""
    transport = httpx.HTTPTransport(local_address=source)
    return httpx.Client(base_url=live.url, timeout=60, transport=transport, headers=headers)


def test_wrong_keys_are_rate_limited_per_address(make_server: Callable[..., LiveServer]) -> None:
    live = make_server(
        GEOSMOOTH_API_KEYS=KEYS["alice"],
        GEOSMOOTH_AUTH_FAILURE_BURST="5",
        GEOSMOOTH_AUTH_FAILURE_RATE="0.01",  # one more guess per 100 s
    )
    with _from(live, "127.0.0.3") as guesser:
        codes = [
            guesser.get("/v1/jobs", headers={"authorization": f"Bearer guess-{i}"}).status_code
            for i in range(5)
        ]
        assert codes == [401] * 5
        blocked = guesser.get("/v1/jobs", headers={"authorization": "Bearer guess-6"})
        assert blocked.status_code == 429, blocked.text
        assert blocked.json()["code"] == "too-many-auth-failures"
        assert 1 <= int(blocked.headers["retry-after"]) <= 100
        # the right key from the guessing address is held too (no oracle) ...
        right = guesser.get("/v1/jobs", headers={"authorization": f"Bearer {KEYS['alice']}"})
        assert right.status_code == 429
        assert guesser.get("/healthz").status_code == 200  # probes are not gated
    # ... while another address is not affected
    with _from(live, "127.0.0.4") as other:
        assert other.get("/v1/jobs", headers={"x-api-key": KEYS["alice"]}).status_code == 200
        assert other.get("/v1/jobs", headers={"x-api-key": "nope"}).status_code == 401


def _slow_then_queued(alice: httpx.Client, bob: httpx.Client) -> list[str]:
    """A slow job on the only worker, then a job of each key queued behind it."""
    files = {"file": ("slow.xyz", encode("xyz", noisy_plane_cloud(40000, seed=11), None))}
    slow = alice.post("/v1/jobs", files=files, data={"params": json.dumps(SLOW_PARAMS)})
    assert slow.status_code == 202, slow.text
    ids = [slow.json()["id"]]
    small = {"file": ("s.xyz", encode("xyz", noisy_plane_cloud(200, seed=2), None))}
    for c in (alice, bob):
        queued = c.post("/v1/jobs", files=small, data={"params": json.dumps({"lam": 1.0})})
        assert queued.status_code == 202, queued.text
        ids.append(queued.json()["id"])
    return ids


def _open_stream(stack: ExitStack, c: httpx.Client, job: str) -> Iterator[str]:
    """An open event stream; keep the returned line iterator (closing it closes the stream)."""
    stream = stack.enter_context(c.stream("GET", f"/v1/jobs/{job}/events"))
    assert stream.status_code == 200
    lines = stream.iter_lines()
    assert next(lines).startswith("id:")  # the stream runs
    return lines


def test_event_streams_over_the_bounds_get_429(make_server: Callable[..., LiveServer]) -> None:
    """Two streams per key, three connections per client address: Alice's third stream is
    refused by her key's bound; with a stream of Bob's the address holds three busy connections
    and a fourth gets an HTTP 429 (not a silent close); both with Retry-After."""
    live = make_server(
        workers=1,
        GEOSMOOTH_API_KEYS=f"{KEYS['alice']},{KEYS['bob']}",
        GEOSMOOTH_EVENTS_MAX_STREAMS="2",
        GEOSMOOTH_MAX_CONNECTIONS_PER_CLIENT="3",
    )
    alice_key, bob_key = (f"Bearer {KEYS[k]}" for k in ("alice", "bob"))
    with (
        _from(live, "127.0.0.5", authorization=alice_key) as a,
        _from(live, "127.0.0.5", authorization=bob_key) as b,
    ):
        slow, alice_job, bob_job = _slow_then_queued(a, b)
    try:
        with ExitStack() as stack:
            clients = [
                stack.enter_context(_from(live, "127.0.0.6", authorization=alice_key))
                for _ in range(3)
            ]
            held = [_open_stream(stack, c, alice_job) for c in clients[:2]]
            third = clients[2].get(f"/v1/jobs/{alice_job}/events")
            assert third.status_code == 429, third.text
            assert third.json()["code"] == "too-many-streams"
            assert int(third.headers["retry-after"]) >= 1
            bobs = stack.enter_context(_from(live, "127.0.0.6", authorization=bob_key))
            clients[2].close()  # its idle connection goes; Bob's stream takes the third place
            held.append(_open_stream(stack, bobs, bob_job))
            with socket.create_connection(("127.0.0.1", live.port), 30, ("127.0.0.6", 0)) as sock:
                sock.sendall(b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
                answer = _read_all(sock)
            head = answer.split(b"\r\n\r\n", 1)[0].decode().lower()
            assert head.startswith("http/1.1 429"), answer
            assert "retry-after: 2" in head and "connection: close" in head
            assert json.loads(answer.split(b"\r\n\r\n", 1)[1])["code"] == "too-many-connections"
            assert len(held) == 3
        # the streams are closed: their slots are free again (polled with a generous bound)
        with _from(live, "127.0.0.6", authorization=alice_key) as again:
            deadline = time.monotonic() + 60
            status = 0
            while time.monotonic() < deadline:
                with again.stream("GET", f"/v1/jobs/{alice_job}/events") as stream:
                    status = stream.status_code
                if status == 200:
                    break
                time.sleep(0.2)
            assert status == 200
    finally:
        with _from(live, "127.0.0.5", authorization=alice_key) as a:
            a.delete(f"/v1/jobs/{slow}")
            a.delete(f"/v1/jobs/{alice_job}")
        with _from(live, "127.0.0.5", authorization=bob_key) as b:
            b.delete(f"/v1/jobs/{bob_job}")


def _read_all(sock: socket.socket) -> bytes:
    chunks = []
    while True:
        data = sock.recv(65536)
        if not data:
            return b"".join(chunks)
        chunks.append(data)
