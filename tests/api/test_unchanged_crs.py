"""Issue 32 on the HTTP API, against the live test server: an input with nothing to smooth
comes back byte-identical (``POST /v1/smooth`` and a job's result, report ``unchanged``), and
the ``crs`` query of ``POST /v1/smooth`` and of a job's result download writes geographic
input in a projected CRS (422, field ``crs``, for a value it cannot take)."""

from __future__ import annotations

import io
import json
import os
from pathlib import Path

import httpx
import numpy as np
import pytest

from tests.api.api_helpers import encode, noisy_sphere, wait_done

REPO = Path(__file__).resolve().parents[2]
SHARED = Path(os.environ.get("GEOSMOOTH_SHARED_DATA") or REPO.parent / "shared" / "data")
pytestmark = pytest.mark.skipif(
    not SHARED.is_dir(), reason="shared data not found (set GEOSMOOTH_SHARED_DATA)"
)
WRENCH, GPX = SHARED / "wrench.dxf", SHARED / "korita-zbevnica.gpx"


def _problem(r: httpx.Response, field: str) -> str:
    assert r.status_code == 422, r.text
    assert r.headers["content-type"].startswith("application/problem+json")
    body = r.json()
    assert body["field"] == field and body["errors"][0]["field"] == field
    return str(body["detail"])


def test_sync_unchanged_is_the_uploaded_bytes(client: httpx.Client) -> None:
    data = WRENCH.read_bytes()
    r = client.post("/v1/smooth", files={"file": ("wrench.dxf", data)},
                    data={"params": "{}"})  # fmt: skip
    assert r.status_code == 200, r.text
    report = json.loads(r.headers["x-geosmooth-report"])
    assert report["noise_found"] is False and report["unchanged"] == "copied"
    assert r.content == data


def test_job_unchanged_result_is_the_uploaded_bytes(client: httpx.Client) -> None:
    data = WRENCH.read_bytes()
    r = client.post("/v1/jobs", files={"file": ("wrench.dxf", data)}, data={"params": "{}"})
    assert r.status_code == 202, r.text
    job = wait_done(client, r.json()["id"])
    assert job["status"] == "succeeded", job
    assert client.get(f"/v1/jobs/{job['id']}/report").json()["unchanged"] == "copied"
    assert client.get(f"/v1/jobs/{job['id']}/result").content == data


def _dxf_points(data: bytes) -> np.ndarray:
    ezdxf = pytest.importorskip("ezdxf")
    doc = ezdxf.read(io.StringIO(data.decode("utf-8", errors="replace")))
    pts = [v for e in doc.modelspace().query("POLYLINE") for v in e.points()]
    pts += [p for e in doc.modelspace().query("LWPOLYLINE") for p in e.vertices_in_wcs()]
    return np.array([[p[0], p[1]] for p in pts])


def test_sync_crs_projects_geographic_input(client: httpx.Client) -> None:
    files = {"file": ("track.gpx", GPX.read_bytes())}
    params = {"params": json.dumps({"lam": 1e-3})}
    r = client.post("/v1/smooth", params={"output_format": "dxf", "crs": "utm"}, files=files,
                    data=params)  # fmt: skip
    assert r.status_code == 200, r.text
    xy = _dxf_points(r.content)
    assert len(xy) and (xy[:, 0] > 1e5).all() and (xy[:, 1] > 1e6).all()  # easting, northing
    code = client.post("/v1/smooth", params={"output_format": "las", "crs": "EPSG:32633"},
                       files=files, data=params)  # fmt: skip
    assert code.status_code == 200, code.text
    laspy = pytest.importorskip("laspy")
    las = laspy.read(io.BytesIO(code.content))
    assert las.header.parse_crs().to_epsg() == 32633


@pytest.mark.parametrize(
    ("name", "out", "crs", "words"),
    [
        ("track.gpx", "dxf", "4326", "not a projected CRS"),
        ("track.gpx", "dxf", "mercator", "EPSG code"),
        ("track.gpx", "gpx", "utm", "projected format"),
        ("sphere.ply", "ply", "utm", "geographic input"),
    ],
)
def test_sync_bad_crs_is_a_422_on_crs(
    client: httpx.Client, name: str, out: str, crs: str, words: str
) -> None:
    if name.endswith(".gpx"):
        data = GPX.read_bytes()
    else:
        pts, faces = noisy_sphere(1, seed=3)
        data = encode("ply", pts, faces)
    query, form = {"output_format": out, "crs": crs}, {"params": json.dumps({"tau": 1e9})}
    r = client.post("/v1/smooth", params=query, files={"file": (name, data)}, data=form)
    assert words in _problem(r, "crs")  # refused before smoothing (tau 1e9 would fail later)


def test_job_result_download_in_a_crs(client: httpx.Client) -> None:
    r = client.post("/v1/jobs", files={"file": ("track.gpx", GPX.read_bytes())},
                    data={"params": json.dumps({"lam": 1e-3})})  # fmt: skip
    assert r.status_code == 202, r.text
    job = wait_done(client, r.json()["id"])
    assert job["status"] == "succeeded", job
    url = f"/v1/jobs/{job['id']}/result"
    ok = client.get(url, params={"output_format": "dxf", "crs": "utm"})
    assert ok.status_code == 200, ok.text
    assert 'filename="' in ok.headers["content-disposition"]
    assert (_dxf_points(ok.content)[:, 0] > 1e5).all()
    assert "projected format" in _problem(client.get(url, params={"crs": "utm"}), "crs")
    assert "not a projected CRS" in _problem(
        client.get(url, params={"output_format": "las", "crs": "4326"}), "crs"
    )
