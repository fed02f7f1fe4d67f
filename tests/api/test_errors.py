"""Every error status answers RFC 9457 problem details naming the field at fault."""

from __future__ import annotations

import json
import random
import socket
from typing import Any

import httpx
import numpy as np
import pytest

from tests.api.api_helpers import (
    LiveServer,
    encode,
    json_geometry,
    noisy_plane_cloud,
    noisy_sphere,
    wait_done,
)

PROBLEM = "application/problem+json"
PTS, FACES = noisy_sphere(1)


def _problem(r: httpx.Response, status: int, field: str | None = None) -> dict[str, Any]:
    assert r.status_code == status, r.text
    assert r.headers["content-type"] == PROBLEM
    body = r.json()
    assert body["status"] == status
    assert body["title"] and body["detail"] and body["type"]
    if field is not None:
        assert body.get("field") == field, body
    return body


def _upload(
    client: httpx.Client, name: str, data: bytes, params: Any = None, **form: str
) -> httpx.Response:
    fields = {"params": json.dumps({"tau": 0.05}) if params is None else params, **form}
    return client.post("/v1/jobs", files={"file": (name, data)}, data=fields)


# --------------------------------------------------------------------------- 400


@pytest.mark.parametrize(
    ("name", "data", "needle"),
    [
        ("bad.ply", b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n", "header"),
        (
            "bad.ply",
            b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\n"
            b"property float y\nproperty float z\nend_header\n0 0 0\n",
            "",
        ),
        ("bad.obj", b"v 0 0 0\nv 1 x 0\n", "line 2"),
        ("bad.xyz", b"0 0 0\n1 1\n", "line 2"),
        ("bad.json", b'{"points": [[0, 0, 0], ', ""),
        ("empty.xyz", b"", ""),
    ],
)
def test_malformed_file_is_400_with_parser_message(
    client: httpx.Client, name: str, data: bytes, needle: str
) -> None:
    body = _problem(_upload(client, name, data), 400, "file")
    assert needle.lower() in body["detail"].lower()


def test_malformed_json_body_is_400(client: httpx.Client) -> None:
    r = client.post(
        "/v1/jobs", content=b'{"geometry": ', headers={"content-type": "application/json"}
    )
    _problem(r, 400, "body")


def test_malformed_multipart_is_400(client: httpx.Client) -> None:
    r = client.post(
        "/v1/jobs",
        content=b'--xyz\r\nContent-Disposition: form-data; name="file"\r\n\r\nabc',
        headers={"content-type": "multipart/form-data; boundary=xyz"},
    )
    assert r.status_code in (400, 422), r.text
    assert r.headers["content-type"] == PROBLEM


# --------------------------------------------------------------------------- 404 / 405


def test_unknown_job_is_404(client: httpx.Client) -> None:
    for path in ("/v1/jobs/0123456789abcdef0123456789abcdef", "/v1/jobs/not-an-id"):
        for suffix in ("", "/result", "/report"):
            _problem(client.get(path + suffix), 404, "job_id")
        _problem(client.delete(path), 404, "job_id")
        _problem(client.post(path + "/cancel"), 404, "job_id")


def test_unknown_route_and_method(client: httpx.Client) -> None:
    _problem(client.get("/v2/nothing"), 404)
    _problem(client.put("/v1/jobs"), 405)
    _problem(client.post("/healthz"), 405)


# --------------------------------------------------------------------------- 409


def test_tau_above_phi0_is_422_at_submit_not_a_failed_job(client: httpx.Client) -> None:
    before = client.get("/v1/jobs", params={"limit": 1}).json()["total"]
    # free displacement: eq. (14) (the default on meshes moves points along normals only, whose
    # phi(0) is that system's limit; tests/core check it)
    free = {"displacement": "free"}
    cases = (({"tau": 1e9, **free}, "params.tau"), ({"rms": 1e6, **free}, "params.rms"))
    for params, field in cases:
        body = _problem(
            _upload(client, "s.ply", encode("ply", PTS, FACES), json.dumps(params)), 422, field
        )
        assert body["code"] == "tau-out-of-range"
        # the valid range is phi(0) of eq. (14): the deviation from the centroid (one part)
        phi0 = float(np.sum((PTS - PTS.mean(axis=0)) ** 2))
        assert body["valid_range"][1] == pytest.approx(phi0, rel=1e-9)  # in tau units
        if field == "params.rms":  # tau = rms^2 n (unit weights), the bound is sqrt(phi0 / n)
            assert body["tau"] == pytest.approx(1e12 * len(PTS), rel=1e-9)
            assert f"{np.sqrt(phi0 / len(PTS)):.6g}" in body["detail"]
    inline = {"geometry": json_geometry(PTS, FACES), "params": {"tau": 1e9}}
    _problem(client.post("/v1/jobs", json=inline), 422, "params.tau")
    assert client.get("/v1/jobs", params={"limit": 1}).json()["total"] == before  # none queued


def test_result_of_unfinished_or_failed_job_is_409(
    client: httpx.Client, server: LiveServer
) -> None:
    """A job whose stored input got corrupted fails; the failure is reported without paths."""
    slow = _upload(
        client,
        "slow.xyz",
        encode("xyz", noisy_plane_cloud(20000, seed=9), None),
        json.dumps({"rms": 0.001, "tolerance": 1e-9, "max_iterations": 200}),
    )
    blockers = [slow.json()["id"]] + [
        _upload(
            client,
            "slow.xyz",
            encode("xyz", noisy_plane_cloud(20000, seed=s), None),
            json.dumps({"rms": 0.001, "tolerance": 1e-9}),
        ).json()["id"]
        for s in (10, 11)
    ]
    r = _upload(client, "s.ply", encode("ply", PTS, FACES), json.dumps({"tau": 0.05}))
    assert r.status_code == 202
    job = r.json()
    body = _problem(client.get(f"/v1/jobs/{job['id']}/result"), 409)
    assert body["code"] == "result-not-ready" and r.headers.get("retry-after") is None
    stored = list((server.data_dir / "jobs" / job["id"]).glob("input.*"))
    assert stored, "the input is stored under data_dir/jobs/<id>/"
    stored[0].write_bytes(b"ply\nformat ascii 1.0\nelement vertex 9\nend_header\n1 2\n")
    done = wait_done(client, job["id"], timeout=120)
    if done["status"] == "succeeded":  # it ran before the corruption: nothing to check
        pytest.skip("the job ran before its input could be corrupted")
    assert done["status"] == "failed"
    error = done["error"]
    assert error["type"].startswith("urn:geosmooth:problem:") and error["detail"]
    assert str(server.data_dir) not in json.dumps(error) and "/" not in error["detail"]
    body = _problem(client.get(f"/v1/jobs/{job['id']}/result"), 409)
    assert body["code"] == "no-result" and body["job_status"] == "failed"
    _problem(client.get(f"/v1/jobs/{job['id']}/report"), 409)
    for other in blockers:
        client.delete(f"/v1/jobs/{other}")


# --------------------------------------------------------------------------- 413


def test_declared_content_length_over_limit_is_413(server: LiveServer) -> None:
    limit = 8 * 1024 * 1024
    with server.client() as c:
        r = c.post(
            "/v1/jobs",
            content=b"0" * (limit + 1),
            headers={"content-type": "application/json"},
        )
    body = _problem(r, 413)
    assert body["code"] == "payload-too-large" and body["max_upload_bytes"] == limit


def test_streamed_body_over_limit_is_413_without_reading_it_all(server: LiveServer) -> None:
    """A chunked upload (no Content-Length) is cut off once it passes the limit."""
    chunk = b"0 0 0\n" * 100_000  # 600 KB
    start = b'--b\r\nContent-Disposition: form-data; name="file"; filename="a.xyz"\r\n\r\n'

    def body() -> Any:
        yield start
        for _ in range(40):  # 24 MB, three times the limit
            yield chunk

    with server.client() as c:
        r = c.post(
            "/v1/jobs",
            content=body(),
            headers={"content-type": "multipart/form-data; boundary=b"},
        )
    _problem(r, 413)


def test_raw_chunked_upload_is_answered_413_while_still_sending(server: LiveServer) -> None:
    """A raw chunked upload is answered 413 once the limit is passed, before it ends."""
    limit = 8 * 1024 * 1024
    with socket.create_connection(("127.0.0.1", server.port), timeout=10) as sock:
        head = (
            b"POST /v1/smooth HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
            b"Transfer-Encoding: chunked\r\n\r\n"
        )
        sock.sendall(head)
        piece = b"x" * 1_000_000
        sent = 0
        try:
            while sent <= limit + len(piece):
                sock.sendall(f"{len(piece):x}\r\n".encode() + piece + b"\r\n")
                sent += len(piece)
        except OSError:
            pass
        answer = sock.recv(65536).decode(errors="replace")
    assert answer.startswith("HTTP/1.1 413"), answer[:200]
    assert "application/problem+json" in answer


def test_too_many_points_for_sync_smooth_is_413(client: httpx.Client) -> None:
    pts, faces = noisy_sphere(4)  # 2562 points > GEOSMOOTH_SYNC_MAX_POINTS=2000
    r = client.post(
        "/v1/smooth", json={"geometry": json_geometry(pts, faces), "params": {"tau": 1}}
    )
    problem = _problem(r, 413, "geometry.points")
    assert problem["max_points"] == 2000 and problem["n_points"] == len(pts)


# --------------------------------------------------------------------------- 415


def test_unknown_format_is_415(client: httpx.Client) -> None:
    _problem(_upload(client, "model.vtp", b"<VTKFile/>"), 415, "format")
    _problem(_upload(client, "scene.blend", b"BLENDER"), 415, "format")
    _problem(_upload(client, "noext", b"<svg/>"), 415, "format")
    _problem(_upload(client, "a.xyz", b"0 0 0\n", format="vtp"), 415, "format")
    r = client.post("/v1/jobs", content=b"0 0 0", headers={"content-type": "text/plain"})
    _problem(r, 415, "content-type")


def test_format_field_overrides_the_extension(client: httpx.Client) -> None:
    r = _upload(client, "points.txt", encode("xyz", PTS, None), format="xyz")
    assert r.status_code == 202, r.text
    assert r.json()["format"] == "xyz"


def test_input_format_names_the_upload_and_format_stays_its_deprecated_alias(
    client: httpx.Client,
) -> None:
    """``input_format`` (upload) and ``output_format`` (download) say which file they are about;
    the former ``format`` keeps working for both, and contradicting pairs are a 422."""
    data = encode("xyz", PTS, None)
    r = _upload(client, "points.txt", data, input_format="xyz")
    assert r.status_code == 202, r.text
    job = r.json()
    assert job["input_format"] == job["format"] == "xyz"
    _problem(_upload(client, "points.txt", data, input_format="xyz", format="ply"), 422,
             "input_format")  # fmt: skip
    _problem(_upload(client, "a.xyz", data, input_format="vtp"), 415, "format")
    r = client.post("/v1/smooth", files={"file": ("p.xyz", data)},
                    data={"params": json.dumps({"lam": 1.0})},
                    params={"output_format": "json"})  # fmt: skip
    assert r.status_code == 200 and "geometry" in r.json(), r.text
    r = client.post("/v1/smooth", files={"file": ("p.xyz", data)},
                    data={"params": json.dumps({"lam": 1.0})},
                    params={"output_format": "json", "format": "obj"})  # fmt: skip
    _problem(r, 422, "output_format")


# --------------------------------------------------------------------------- 422


@pytest.mark.parametrize(
    ("params", "field"),
    [
        ({"tau": -1}, "params.tau"),
        ({"tau": 0.1, "lam": 1}, "params"),
        ({"rms": 0.1, "lam": 1}, "params"),
        ({"tau": 0.1, "k": 1}, "params.k"),
        ({"tau": 0.1, "laplacian": "magic"}, "params.laplacian"),
        ({"tau": 0.1, "bogus": 1}, "params.bogus"),
        ({"tau": "nan"}, "params.tau"),
        ([1, 2], "params"),
    ],
)
def test_invalid_parameters_are_422_before_queueing(
    client: httpx.Client, params: Any, field: str
) -> None:
    before = client.get("/v1/jobs").json()["total"]
    body = _problem(_upload(client, "s.ply", encode("ply", PTS, FACES), json.dumps(params)), 422)
    assert body["field"] == field and body["errors"][0]["field"] == field
    r = client.post("/v1/jobs", json={"geometry": json_geometry(PTS, FACES), "params": params})
    assert _problem(r, 422)["field"] == field
    assert client.get("/v1/jobs").json()["total"] == before  # nothing was queued


def test_params_not_json_and_missing_parts_are_422(client: httpx.Client) -> None:
    _problem(_upload(client, "s.ply", encode("ply", PTS, FACES), "{tau: 1"), 422, "params")
    r = client.post("/v1/jobs", data={"params": '{"tau": 1}'}, files={"other": ("a.ply", b"x")})
    _problem(r, 422)
    r = client.post("/v1/jobs", files={"file": ("a.ply", encode("ply", PTS, FACES))})
    _problem(r, 422, "params")
    r = client.post("/v1/jobs", json={"params": {"tau": 1}})
    _problem(r, 422, "geometry")


@pytest.mark.parametrize(
    ("geometry", "field"),
    [
        ({"points": [[0, 0, 0], [1, 0, 0], [0, 1, 0]], "faces": [[0, 1, 7]]}, "geometry"),
        ({"points": [[0, 0, 0], [1, 0, 0]], "face": [[0, 1, 2]]}, "geometry"),
        ({"points": []}, "geometry"),
        ({"points": [[0, 0, 0], [1, 1, 1]], "weights": [1, -1]}, "geometry.weights"),
    ],
)
def test_invalid_inline_geometry_is_422(
    client: httpx.Client, geometry: dict[str, Any], field: str
) -> None:
    r = client.post("/v1/jobs", json={"geometry": geometry, "params": {"tau": 0.1}})
    _problem(r, 422, field)


def test_non_finite_coordinates_are_422(client: httpx.Client) -> None:
    r = client.post(
        "/v1/jobs",
        content=b'{"geometry": {"points": [[0, 0, 0], [1, NaN, 0]]}, "params": {"tau": 1}}',
        headers={"content-type": "application/json"},
    )
    body = _problem(r, 422, "geometry.points")
    assert body["indices"] == [1]
    r = _upload(client, "nan.xyz", b"0 0 0\n1 nan 0\n2 2 2\n")
    assert r.status_code in (400, 422) and r.headers["content-type"] == PROBLEM


def test_sync_tau_out_of_range_is_422_with_valid_range(client: httpx.Client) -> None:
    r = client.post(
        "/v1/smooth", json={"geometry": json_geometry(PTS, FACES), "params": {"tau": 1e9}}
    )
    body = _problem(r, 422, "params.tau")
    assert body["code"] == "tau-out-of-range"
    assert body["valid_range"][0] == 0 and 0 < body["valid_range"][1] < 1e9


def test_query_validation_is_422_problem(client: httpx.Client) -> None:
    _problem(client.get("/v1/jobs", params={"limit": 0}), 422, "limit")
    _problem(client.get("/v1/jobs", params={"status": "sleeping"}), 422, "status")
    job = client.post(
        "/v1/jobs", json={"geometry": json_geometry(PTS, FACES), "params": {"tau": 0.05}}
    ).json()
    _problem(client.get(f"/v1/jobs/{job['id']}/result", params={"format": "vtp"}), 422, "format")


def test_server_survives_all_of_the_above(client: httpx.Client) -> None:
    assert client.get("/healthz").json() == {"status": "ok"}
    job = client.post(
        "/v1/jobs", json={"geometry": json_geometry(PTS, FACES), "params": {"tau": 0.05}}
    ).json()
    assert wait_done(client, job["id"])["status"] == "succeeded"


@pytest.mark.parametrize("fmt", ["ply", "obj", "xyz", "json"])
def test_garbage_and_hostile_files_never_give_500(client: httpx.Client, fmt: str) -> None:
    rng = random.Random(fmt)
    hostile = [
        bytes(rng.randrange(256) for _ in range(2000)),
        b"[" * 100_000,
        b'{"points": ' + b"[" * 100_000,
        b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000000\n"
        b"property float x\nproperty float y\nproperty float z\nend_header\n\x00\x00",
        b"v 1e999 0 0\nv 0 0 0\nv 1 1 1\nf 1 2 3\n",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n".encode("utf-16"),
    ]
    for data in hostile:
        r = _upload(client, f"x.{fmt}", data)
        assert r.status_code in (202, 400, 413, 422), r.text
        assert r.status_code == 202 or r.headers["content-type"] == PROBLEM
    r = client.post(
        "/v1/jobs", content=b"[" * 100_000, headers={"content-type": "application/json"}
    )
    _problem(r, 400, "body")
    assert client.get("/healthz").status_code == 200
