"""``POST /v1/info``: describe() of an upload or inline geometry, plus the display preview.

phi(0) is checked against eq. (14): with unit weights, no fixed points and one connected
component, the fully smoothed shape is the centroid, so phi(0) = sum_i ||p_i - mean(p)||^2.
"""

from __future__ import annotations

import base64
import json
from typing import Any

import httpx
import numpy as np
import pytest

from service.core.info import describe
from service.io import read_geometry
from tests.web.web_helpers import SAMPLES, WebServer


def info(client: httpx.Client, **kwargs: Any) -> httpx.Response:
    return client.post("/v1/info", **kwargs)


def decode(text: str, dtype: str, width: int) -> np.ndarray:
    return np.frombuffer(base64.b64decode(text), dtype=dtype).reshape(-1, width)


def centroid_phi0(points: np.ndarray) -> float:
    return float(np.sum((points - points.mean(axis=0)) ** 2))


@pytest.fixture
def client(web_server: WebServer) -> Any:
    with web_server.client() as c:
        yield c


def test_mesh_upload_without_params(client: httpx.Client) -> None:
    path = SAMPLES / "noisy-sphere.ply"
    response = info(client, files={"file": (path.name, path.read_bytes())})
    assert response.status_code == 200, response.text
    out = response.json()
    points = read_geometry(path).geometry.points
    n = len(points)
    assert (out["n_points"], out["dimension"], out["kind"]) == (642, 3, "mesh")
    assert (out["n_faces"], out["n_edges"], out["n_polylines"]) == (1280, 1920, 0)
    assert out["input_format"] == out["format"] == "ply" and out["filename"] == path.name
    assert out["weld"] is False
    assert out["bbox"]["min"] == pytest.approx(points.min(axis=0).tolist())
    assert out["bbox"]["max"] == pytest.approx(points.max(axis=0).tolist())
    # default displacement for meshes moves points along their normals: its phi(0) is the one
    # smooth() enforces; eq. (14) is the phi(0) of free displacement
    assert out["phi0"] == pytest.approx(describe(read_geometry(path).geometry)["phi0"], rel=1e-8)
    free = info(client, files={"file": (path.name, path.read_bytes())},
                data={"params": json.dumps({"displacement": "free"})}).json()
    assert free["phi0"] == pytest.approx(centroid_phi0(points), rel=1e-8)
    assert out["tau_range"] == pytest.approx([0.0, out["phi0"]])
    assert out["rms_range"][1] == pytest.approx(np.sqrt(out["phi0"] / n), rel=1e-12)
    assert out["preview"] is None
    for key in ("sigma_estimate", "suggested_tau", "suggested_rms", "mean_spacing", "notes"):
        assert key in out


def test_curve_preview_in_file_order(client: httpx.Client) -> None:
    path = SAMPLES / "noisy-helix.obj"
    files = {"file": (path.name, path.read_bytes())}
    # the report's ends (pulled): the lambda -> 0 limit is the centroid (eq. 14)
    report_ends = {"params": json.dumps({"ends": "pulled", "tau": 1})}
    response = info(client, params={"preview": "true"}, files=files, data=report_ends)
    assert response.status_code == 200, response.text
    out = response.json()
    assert (out["kind"], out["n_polylines"], out["n_points"]) == ("curve", 1, 200)
    points = read_geometry(path).geometry.points
    assert out["phi0"] == pytest.approx(centroid_phi0(points), rel=1e-8)
    # the default pins the open curve's ends (issue 21): the limit is the straight segment
    # between them at evenly spaced parameters (uniform weights), reached at the engine's
    # lambda floor to within 1e-3
    t = np.linspace(0.0, 1.0, len(points))[:, None]
    line = float(((points - (points[0] + t * (points[-1] - points[0]))) ** 2).sum())
    assert line * (1 - 1e-3) <= info(client, files=files).json()["phi0"] <= line
    preview = out["preview"]
    xyz = decode(preview["positions"], "<f4", 3).astype(np.float64) + preview["origin"]
    extent = float(np.ptp(points, axis=0).max())
    np.testing.assert_allclose(xyz, points, rtol=0, atol=extent * 1e-7)
    segments = decode(preview["segments"], "<u4", 2)
    np.testing.assert_array_equal(segments, np.c_[np.arange(199), np.arange(1, 200)])
    assert preview["faces"] is None and preview["dimension"] == 3


def test_params_change_phi0(client: httpx.Client) -> None:
    """Fixed curve ends: the limit is no longer the centroid, so phi(0) changes."""
    path = SAMPLES / "noisy-helix.obj"
    files = {"file": (path.name, path.read_bytes())}
    pulled = {"params": json.dumps({"ends": "pulled", "tau": 1})}  # the report's ends
    free = info(client, files=files, data=pulled).json()["phi0"]
    fixed = info(client, files=files, data={"params": json.dumps({"fix_boundary": True, "tau": 1})})
    assert fixed.status_code == 200, fixed.text
    assert 0 < fixed.json()["phi0"] != pytest.approx(free)


def test_inline_json_welded_2d(client: httpx.Client) -> None:
    """A triangle soup in 2-D: welding merges the copies; the preview keeps the file's 6."""
    tri = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 0.0], [1.0, 1.0], [0.0, 1.0]]
    body = {"geometry": {"points": tri, "faces": [[0, 1, 2], [3, 4, 5]]}, "weld": True}
    response = info(client, params={"preview": "true"}, json=body)
    assert response.status_code == 200, response.text
    out = response.json()
    assert (out["n_points"], out["dimension"], out["weld"], out["format"]) == (4, 2, True, "json")
    preview = out["preview"]
    assert preview["n_points"] == 6 and preview["dimension"] == 2
    xyz = decode(preview["positions"], "<f4", 3) + np.array(preview["origin"])
    np.testing.assert_allclose(xyz[:, :2], tri, atol=1e-7)
    assert np.all(xyz[:, 2] == 0)
    np.testing.assert_array_equal(decode(preview["faces"], "<u4", 3), [[0, 1, 2], [3, 4, 5]])
    four = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    assert out["phi0"] == pytest.approx(centroid_phi0(four), rel=1e-8)


@pytest.mark.parametrize(
    ("kwargs", "status", "field"),
    [
        ({"files": {"file": ("empty.ply", b"")}}, 400, "file"),
        ({"files": {"file": ("shape.stp", b"solid")}}, 415, "format"),
        (
            {"files": {"file": ("a.xyz", b"0 0 0\n1 0 0\n0 1 0\n")}, "data": {"params": "{"}},
            422,
            "params",
        ),
        (
            {
                "files": {"file": ("a.xyz", b"0 0 0\n1 0 0\n0 1 0\n")},
                "data": {"params": '{"k": 1, "tau": 1}'},
            },
            422,
            "params.k",
        ),
        ({"files": {"file": ("a.ply", b"ply\nformat ascii 1.0\nelement vertex 2\n")}}, 400, "file"),
        ({"json": {"geometry": {"points": "nope"}}}, 422, "geometry"),
        ({"json": {"points": [[0, 0]]}}, 422, "points"),
        ({"content": b"x", "headers": {"content-type": "text/plain"}}, 415, "content-type"),
    ],
)
def test_bad_input_is_a_problem_naming_the_field(
    client: httpx.Client, kwargs: dict[str, Any], status: int, field: str
) -> None:
    response = info(client, **kwargs)
    assert response.status_code == status, response.text
    assert response.headers["content-type"] == "application/problem+json"
    assert response.json()["field"] == field
