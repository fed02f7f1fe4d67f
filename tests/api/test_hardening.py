"""Browser-borne attacks, protocol errors and numeric extremes against a live server:
forged Host and Origin headers, CORS, Allow headers, problem+json for protocol-level errors,
kept-alive connections after errors, request ids and structured logs, and no 5xx or NaN for
extreme numbers."""

from __future__ import annotations

import json
import math
import socket
from typing import Any

import httpx
import numpy as np
import pytest

from tests.api.api_helpers import LiveServer, encode, json_geometry, noisy_plane_cloud, noisy_sphere

PROBLEM = "application/problem+json"
PTS, FACES = noisy_sphere(1)


def _raw(port: int, payload: bytes, timeout: float = 10.0) -> bytes:
    """Send ``payload``; read one response (head and ``Content-Length`` bytes of body)."""
    with socket.create_connection(("127.0.0.1", port), timeout=timeout) as sock:
        sock.sendall(payload)
        data = b""
        while b"\r\n\r\n" not in data and (chunk := sock.recv(65536)):
            data += chunk
        head, _, body = data.partition(b"\r\n\r\n")
        length = next(
            (
                int(line.split(b":")[1])
                for line in head.lower().split(b"\r\n")
                if line.startswith(b"content-length:")
            ),
            0,
        )
        while len(body) < length and (chunk := sock.recv(65536)):
            body += chunk
    return head + b"\r\n\r\n" + body


# --------------------------------------------------------------------------- Host, Origin, CORS


@pytest.mark.parametrize("host", ["evil.example", "127.0.0.1.evil.example", "10.0.0.1:8000"])
def test_forged_host_is_refused(client: httpx.Client, host: str) -> None:
    r = client.get("/v1/jobs", headers={"Host": host})
    assert r.status_code == 400 and r.headers["content-type"] == PROBLEM
    assert r.json()["code"] == "host-not-allowed"
    for ok in ("127.0.0.1", "localhost:1234", "[::1]:80"):
        assert client.get("/v1/jobs", headers={"Host": ok}).status_code == 200


def test_cross_origin_writes_without_a_key_are_refused(client: httpx.Client) -> None:
    form = {"params": json.dumps({"tau": 0.05})}
    files = {"file": ("s.ply", encode("ply", PTS, FACES))}
    for headers in (
        {"Origin": "https://evil.example"},
        {"Origin": "null"},  # sandboxed iframes, file:// pages
        {"Sec-Fetch-Site": "cross-site"},
        {"Origin": f"http://localhost:{client.base_url.port + 1}"},  # another port: another origin
    ):
        r = client.post("/v1/jobs", files=files, data=form, headers=headers)
        assert r.status_code == 403 and r.json()["code"] == "cross-origin-refused", headers
        r = client.delete("/v1/jobs/0123456789abcdef0123456789abcdef", headers=headers)
        assert r.status_code == 403
        assert client.get("/v1/jobs", headers=headers).status_code == 200  # reads are fine
    same = {"Origin": str(client.base_url).rstrip("/"), "Sec-Fetch-Site": "same-origin"}
    assert client.post("/v1/jobs", files=files, data=form, headers=same).status_code == 202
    keyed = {"Origin": "https://evil.example", "X-API-Key": "anything"}  # no keys: ignored
    assert client.post("/v1/jobs", files=files, data=form, headers=keyed).status_code == 202


def test_cors_is_off_by_default_and_configurable(client: httpx.Client, tight: LiveServer) -> None:
    preflight = {"Origin": "https://app.example", "Access-Control-Request-Method": "POST"}
    r = client.options("/v1/jobs", headers=preflight)
    assert "access-control-allow-origin" not in r.headers
    assert "access-control-allow-origin" not in client.get("/v1/jobs", headers=preflight).headers
    with tight.client() as c:  # GEOSMOOTH_CORS_ORIGINS=https://app.example
        r = c.options(
            "/v1/jobs", headers={**preflight, "Access-Control-Request-Headers": "x-api-key"}
        )
        assert r.status_code == 200
        assert r.headers["access-control-allow-origin"] == "https://app.example"
        r = c.get("/v1/jobs", headers={"Origin": "https://app.example"})
        assert r.headers["access-control-allow-origin"] == "https://app.example"
        assert "x-request-id" in r.headers["access-control-expose-headers"].lower()
        r = c.options("/v1/jobs", headers={**preflight, "Origin": "https://evil.example"})
        assert r.headers.get("access-control-allow-origin") != "https://evil.example"
        files = {"file": ("s.ply", encode("ply", PTS, FACES))}
        r = c.post(
            "/v1/jobs",
            files=files,
            data={"params": '{"tau": 0.05}'},
            headers={"Origin": "https://app.example"},
        )
        assert r.status_code == 202  # a trusted origin may write


# --------------------------------------------------------------------------- protocol level


def test_wrong_methods_answer_405_with_the_right_allow_header(client: httpx.Client) -> None:
    for method, path, allow in (
        ("PATCH", "/v1/jobs", "GET, POST"),
        ("PUT", "/v1/jobs/0123456789abcdef0123456789abcdef", "GET, DELETE"),
        ("POST", "/v1/jobs/x/result", "GET"),
        ("GET", "/v1/smooth", "POST"),
        ("DELETE", "/healthz", "GET"),
    ):
        r = client.request(method, path)
        assert r.status_code == 405 and r.headers["content-type"] == PROBLEM
        assert r.headers["allow"] == allow, (method, path, r.headers.get("allow"))


@pytest.mark.parametrize(
    "payload",
    [
        b"GARBAGE\r\n\r\n",
        b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\nBad Header\r\n\r\n",
        b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Big: " + b"a" * 70_000 + b"\r\n\r\n",
        b"POST /v1/jobs HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: 5\r\n"
        b"Transfer-Encoding: chunked\r\n\r\n",
    ],
)
def test_protocol_errors_are_problem_json(server: LiveServer, payload: bytes) -> None:
    answer = _raw(server.port, payload)
    head, _, body = answer.partition(b"\r\n\r\n")
    assert head.startswith(b"HTTP/1.1 4"), answer[:200]
    assert b"content-type: application/problem+json" in head.lower(), head
    problem = json.loads(body)
    assert problem["status"] == int(head.split()[1]) and problem["detail"]


def test_connection_stays_open_after_client_errors(server: LiveServer) -> None:
    requests = [
        b"GET /v1/jobs/nope HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n",  # 404
        b"GET /v1/jobs?offset=-1 HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n",  # 422
        b"POST /v1/smooth HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
        b"Content-Length: 3\r\n\r\n{x}",  # 400
        b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n",
    ]
    with socket.create_connection(("127.0.0.1", server.port), timeout=30) as sock:
        stream = sock.makefile("rb")
        for request, status in zip(requests, (404, 422, 400, 200), strict=True):
            sock.sendall(request)
            line = stream.readline()
            assert line.startswith(f"HTTP/1.1 {status}".encode()), line
            headers = {}
            while (h := stream.readline()) not in (b"\r\n", b""):
                name, _, value = h.decode().partition(":")
                headers[name.lower()] = value.strip()
            assert headers.get("connection") != "close"
            stream.read(int(headers["content-length"]))


def test_unexpected_errors_do_not_reach_the_server(tmp_path: Any) -> None:
    """The last-resort answer is sent by the app, so uvicorn keeps the connection alive."""
    import anyio

    from service.api.app import create_app
    from service.settings import Settings

    class Broken:
        def get(self, job_id: str, *, tenant: Any = None) -> Any:
            raise ZeroDivisionError("internal detail")

    app = create_app(Settings(data_dir=tmp_path), queue=Broken())  # type: ignore[arg-type]
    app.state.queue_started = True
    sent: list[dict[str, Any]] = []

    async def receive() -> dict[str, Any]:
        return {"type": "http.request", "body": b"", "more_body": False}

    async def send(message: dict[str, Any]) -> None:
        sent.append(message)

    scope = {
        "type": "http",
        "method": "GET",
        "path": "/v1/jobs/abc",
        "raw_path": b"/v1/jobs/abc",
        "query_string": b"",
        "headers": [(b"host", b"localhost")],
        "client": ("127.0.0.1", 1),
        "server": ("127.0.0.1", 80),
        "scheme": "http",
        "root_path": "",
        "http_version": "1.1",
    }
    anyio.run(app, scope, receive, send)  # returns normally: nothing for the server to close
    assert sent[0]["status"] == 500
    body = json.loads(sent[1]["body"])
    assert body["code"] == "internal" and "internal detail" not in json.dumps(body)
    assert body["request_id"]


# --------------------------------------------------------------------------- numbers, paths, logs


@pytest.mark.parametrize(
    "query",
    [
        {"offset": 10**30},
        {"page": 10**30},
        {"limit": 10**12},
        {"offset": "9" * 5000},
        {"page": 10**8, "size": 500},
    ],
)
def test_huge_paging_values_are_422(client: httpx.Client, query: dict[str, Any]) -> None:
    r = client.get("/v1/jobs", params=query)
    assert r.status_code == 422 and r.headers["content-type"] == PROBLEM, r.text


def _no_nan(obj: Any) -> None:
    text = json.dumps(obj)
    assert "NaN" not in text and "Infinity" not in text, text[:300]


@pytest.mark.parametrize(
    "geometry",
    [
        {"points": (noisy_plane_cloud(60) * 1e300).tolist()},
        {"points": (noisy_plane_cloud(60) * 1e-300).tolist()},
        {"points": (noisy_plane_cloud(60) + np.array([6.6e5, 5.6e6, 0.0])).tolist()},
        {"points": noisy_plane_cloud(60).tolist(), "weights": [1e200] * 60},
        {"points": noisy_plane_cloud(60).tolist(), "weights": [1e-200] * 60},
        {"points": [[1.7e308, 0, 0], [-1.7e308, 0, 0], [0, 1, 0], [0, 0, 1]]},
    ],
)
def test_extreme_numbers_never_give_5xx_or_nan(
    client: httpx.Client, geometry: dict[str, Any]
) -> None:
    for params in ({"lam": 1.0}, {"rms": 1e-3}):
        body = {"geometry": geometry, "params": params}
        r = client.post("/v1/smooth", json=body, params={"format": "json"})
        assert r.status_code in (200, 413, 422), r.text
        _no_nan(r.json())
        if r.status_code == 200:
            points = np.asarray(r.json()["geometry"]["points"], dtype=float)
            assert np.all(np.isfinite(points))
        r = client.post("/v1/jobs", json=body)
        assert r.status_code in (202, 413, 422), r.text
        _no_nan(r.json())


def test_errors_carry_no_server_paths(client: httpx.Client, server: LiveServer) -> None:
    bad = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n"
    for name in ("bad.ply", "noext"):
        r = client.post("/v1/smooth", files={"file": (name, bad)}, data={"params": '{"lam": 1}'})
        assert r.status_code == 400, r.text
        text = r.text
        assert str(server.data_dir) not in text and "/tmp" not in text and "spool" not in text


def test_request_id_is_echoed_and_logged_as_json(client: httpx.Client, server: LiveServer) -> None:
    r = client.get("/v1/jobs/nope", headers={"X-Request-ID": "trace-42.a"})
    assert r.headers["x-request-id"] == "trace-42.a"
    generated = client.get("/healthz").headers["x-request-id"]
    assert len(generated) == 32
    weird = client.get("/healthz", headers={"X-Request-ID": "bad id\twith spaces"})
    assert weird.headers["x-request-id"] != "bad id\twith spaces"
    job = client.post(
        "/v1/jobs",
        json={"geometry": json_geometry(PTS, FACES), "params": {"tau": 0.05}},
        headers={"X-Request-ID": "submit-7"},
    ).json()
    records = server.records()
    lines = [r for r in records if r.get("request_id") == "trace-42.a"]
    assert any(r["event"] == "request" and r["status"] == 404 for r in lines), lines
    submitted = [r for r in records if r.get("event") == "job.submitted"]
    assert any(r["job_id"] == job["id"] and r["request_id"] == "submit-7" for r in submitted)
    for record in records:
        assert {"event", "level", "timestamp"} <= set(record), record
        assert not any(isinstance(v, float) and not math.isfinite(v) for v in record.values())
