"""The client against the real service (uvicorn on loopback, started by the session fixture).

Results are checked against independent computations: phi recomputed from the arrays sent and
received, the report's own identities, the downloaded file parsed by the tests' own codecs.
"""

from __future__ import annotations

import asyncio
import json
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from geosmooth_client import (
    AsyncClient,
    BadRequest,
    Client,
    Conflict,
    InvalidInput,
    JobFailed,
    JobInterrupted,
    NotFound,
    UnsupportedMediaType,
    WaitTimeout,
)

from tests.api.api_helpers import (
    LiveServer,
    encode,
    noisy_helix,
    noisy_plane_cloud,
    noisy_sphere,
    parse_points,
    phi,
)

SPEC = json.loads((Path(__file__).resolve().parents[2] / "openapi" / "openapi.json").read_text())
HAS_EVENTS = "/v1/jobs/{job_id}/events" in SPEC["paths"]
# seconds of solving with several lambda iterations on a 30K cloud: the report's rational search
# with SuperLU (six factorizations; the default path's one Lanczos run takes about one second)
SLOW = {"tau": 1, "tolerance": 1e-9, "search": "rational", "solver": "superlu"}


def _slow_cloud(seed: int) -> bytes:
    return encode("xyz", noisy_plane_cloud(30000, seed=seed), None)


def test_smooth_a_file_with_progress(live: LiveServer, tmp_path: Path) -> None:
    pts, faces = noisy_sphere(2, seed=50)
    src = tmp_path / "sphere.ply"
    src.write_bytes(encode("ply", pts, faces))
    seen: list[Any] = []
    with Client(live.url) as client:
        result = client.smooth(src, tau=0.05, progress=seen.append)
        assert client.uses_events is HAS_EVENTS  # events where the service has them, else polls
        report = result.report
        after = parse_points(result.download(), "ply")
        converted = parse_points(result.download("obj"), "obj")
        saved = result.save(tmp_path / "out.json")
        with pytest.raises(InvalidInput, match="cannot write gpx: GPX holds lines, not faces"):
            result.download("gpx")  # a mesh as GPX: refused (422 naming format), not scrambled
    assert seen[0].status == "queued" and seen[-1].status == "succeeded"
    assert result.job.filename == "sphere.ply" and result.job.format == "ply"
    assert report.converged and abs(report.phi - 0.05) / 0.05 <= 1e-3
    assert report.phi == pytest.approx(phi(pts, after), rel=1e-9)  # phi from the two files
    np.testing.assert_array_equal(converted, after)
    np.testing.assert_array_equal(parse_points(saved.read_bytes(), "json"), after)


def test_smooth_arrays_and_a_mapping(live: LiveServer) -> None:
    curve = noisy_helix(120, seed=51)
    edges = np.column_stack([np.arange(119), np.arange(1, 120)])
    pts, faces = noisy_sphere(1, seed=52)
    with Client(live.url) as client:
        cloud = client.smooth(noisy_plane_cloud(300, seed=53), rms=0.005).arrays()
        helix = client.smooth({"points": curve, "edges": edges}, lam=0.5).arrays()
        sphere = client.smooth({"points": pts, "faces": faces}, tau=0.01)
        arrays = sphere.arrays()
    assert cloud.points.shape == (300, 3) and cloud.faces is None
    assert helix.points.shape == (120, 3)
    np.testing.assert_array_equal(helix.edges, edges)
    np.testing.assert_array_equal(arrays.faces, faces)
    assert sphere.report.phi == pytest.approx(phi(pts, arrays.points), rel=1e-9)


def test_bytes_need_a_format_or_a_name(live: LiveServer) -> None:
    data = encode("xyz", noisy_plane_cloud(200, seed=54), None)
    with Client(live.url) as client:
        assert client.smooth(data, fmt="xyz", rms=0.01).job.format == "xyz"
        assert client.smooth(data, filename="c.xyz", rms=0.01).job.filename == "c.xyz"


def test_refusals_are_typed_and_name_the_field(live: LiveServer) -> None:
    with Client(live.url) as client:
        with pytest.raises(BadRequest) as bad:
            client.submit(b"0 0 0\n1 1\n", fmt="xyz", tau=1)
        assert bad.value.field == "file" and "line 2" in bad.value.detail
        with pytest.raises(InvalidInput) as invalid:
            client.submit(b"0 0 0\n1 1 1\n2 2 2\n", fmt="xyz", tau=-1)
        assert invalid.value.field == "params.tau"
        assert [e.field for e in invalid.value.errors] == ["params.tau"]
        with pytest.raises(UnsupportedMediaType):
            client.submit(b"<svg/>", filename="shape.svg", tau=1)
        with pytest.raises(NotFound) as missing:
            client.get("0123456789abcdef")
        assert missing.value.status == 404
        with pytest.raises(NotFound):
            client.wait("0123456789abcdef", timeout=10)


def test_tau_beyond_phi0_is_refused_or_fails_with_the_valid_range(live: LiveServer) -> None:
    pts, faces = noisy_sphere(1, seed=55)
    with Client(live.url) as client:
        try:  # a 422 at submit once the service checks the range up front, a failed job before
            client.smooth({"points": pts, "faces": faces}, tau=1e9, displacement="free")
        except InvalidInput as exc:
            field, valid = exc.field, exc.problem.get("valid_range")
        except JobFailed as exc:
            assert exc.job.status == "failed" and exc.code == "tau-out-of-range"
            field, valid = exc.field, exc.job.error.extra.get("valid_range")  # type: ignore[union-attr]
    assert field == "params.tau"
    phi0 = float(((pts - pts.mean(axis=0)) ** 2).sum())  # eq. 14 (free displacement), one part
    assert valid[0] == 0 and valid[1] == pytest.approx(phi0, rel=1e-9)


def test_timeout_and_ctrl_c_leave_no_job_running(live: LiveServer) -> None:
    with Client(live.url) as client:
        with pytest.raises(WaitTimeout) as late:
            client.smooth(_slow_cloud(56), fmt="xyz", timeout=0.5, **SLOW)
        job_id = late.value.job_id
        assert client.get(job_id).status == "cancelled"

        def interrupt(job: Any) -> None:
            if job.status == "queued":
                raise KeyboardInterrupt  # as Ctrl-C would, while the client waits

        with pytest.raises(JobInterrupted) as stopped:
            client.smooth(_slow_cloud(57), fmt="xyz", progress=interrupt, **SLOW)
        assert stopped.value.status == "cancelled" and stopped.value.job_id
        assert client.get(stopped.value.job_id).status == "cancelled"


def test_job_lifecycle_endpoints(live: LiveServer) -> None:
    with Client(live.url) as client:
        job = client.submit(_slow_cloud(58), fmt="xyz", **SLOW)
        with pytest.raises(Conflict) as early:
            client.download(job.id)
        assert early.value.retry_after == 1.0
        listed = {j.id for j in client.iter_jobs(status=None, page_size=2)}
        assert job.id in listed and client.list(limit=1).total >= len(listed)
        cancelled = client.cancel(job.id)
        assert cancelled.status == "cancelled" and client.cancel(job.id).status == "cancelled"
        client.delete(job.id)
        with pytest.raises(NotFound):
            client.get(job.id)
        running = client.submit(_slow_cloud(59), fmt="xyz", **SLOW)
        client.delete(running.id)  # cancels, then deletes
        with pytest.raises(NotFound):
            client.get(running.id)


def test_async_client(live: LiveServer) -> None:
    pts, faces = noisy_sphere(1, seed=60)

    async def run() -> None:
        async with AsyncClient(live.url) as client:
            seen: list[Any] = []
            result = await client.smooth({"points": pts, "faces": faces}, tau=0.01,
                                         progress=seen.append)  # fmt: skip
            arrays = await result.arrays()
            assert result.report.phi == pytest.approx(phi(pts, arrays.points))
            assert seen[-1].status == "succeeded"
            with pytest.raises(BadRequest):
                await client.submit(b"0 0 0\n1 1\n", fmt="xyz", tau=1)
            task = asyncio.ensure_future(client.smooth(_slow_cloud(61), fmt="xyz", **SLOW))
            while not [j async for j in client.iter_jobs(status="running")]:
                await asyncio.sleep(0.05)
            task.cancel()  # as asyncio.run does on Ctrl-C
            with pytest.raises(asyncio.CancelledError):
                await task
            page = await client.list(status="running")
            assert page.total == 0  # the job was cancelled before the cancellation propagated

    deadline = time.monotonic() + 60
    asyncio.run(asyncio.wait_for(run(), deadline - time.monotonic()))
