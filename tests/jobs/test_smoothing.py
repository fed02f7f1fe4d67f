"""The real job function end to end: files written with service.io, smoothed by service.core."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable

import numpy as np
import pytest

from service.core.geometry import Geometry
from service.core.params import SmoothingParams
from service.io import GeometryDocument, read_geometry, write_geometry
from service.jobs import JobStatus, LocalQueue
from service.jobs.config import LocalConfig
from service.jobs.queue import NewJob
from service.jobs.runner import DEFAULT_RUNNER
from tests.jobs.jobs_helpers import wait_finished

MakeQueue = Callable[..., LocalQueue]


def noisy_ring(n: int = 200, noise: float = 0.02) -> Geometry:
    """A closed polyline around the unit circle with Gaussian noise."""
    rng = np.random.default_rng(7)
    t = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    points = np.c_[np.cos(t), np.sin(t), np.zeros(n)] + rng.normal(0.0, noise, (n, 3))
    edges = np.c_[np.arange(n), (np.arange(n) + 1) % n]
    return Geometry(points, edges=edges)


def noisy_sphere(noise: float = 0.01) -> Geometry:
    """An icosphere (162 vertices) with Gaussian noise."""
    trimesh = pytest.importorskip("trimesh")
    sphere = trimesh.creation.icosphere(subdivisions=2)
    rng = np.random.default_rng(3)
    return Geometry(sphere.vertices + rng.normal(0.0, noise, sphere.vertices.shape), sphere.faces)


def as_bytes(geometry: Geometry, fmt: str) -> bytes:
    return write_geometry(GeometryDocument.from_geometry(geometry), fmt)


@pytest.fixture
def real_queue(make_queue: MakeQueue) -> LocalQueue:
    return make_queue(runner=DEFAULT_RUNNER)


def test_default_runner_is_the_real_one(make_queue: MakeQueue) -> None:
    defaults = {f.name: f.default for f in dataclasses.fields(LocalConfig)}
    assert defaults["runner"] == DEFAULT_RUNNER
    assert make_queue(start=False, runner=DEFAULT_RUNNER).pool.runner == DEFAULT_RUNNER


def test_polyline_job_meets_tau(real_queue: LocalQueue) -> None:
    ring = noisy_ring()
    params = SmoothingParams(tau=0.05)
    rec = real_queue.submit(NewJob.check(as_bytes(ring, "obj"), "obj", params, filename="ring.obj"))
    done = wait_finished(real_queue, rec.id, timeout=60)
    assert done.status is JobStatus.SUCCEEDED, done.problem

    report = json.loads(real_queue.files.report(rec.id).read_text())
    assert report == done.report
    assert report["tau"] == pytest.approx(0.05)
    assert abs(report["phi"] - 0.05) / 0.05 <= params.tolerance
    assert report["converged"] is True
    assert done.relative_error == pytest.approx(report["relative_error"])
    assert done.iteration == report["iterations"] >= 1

    smoothed = np.load(real_queue.files.result_points(rec.id))
    doc = real_queue.result(rec.id)
    assert isinstance(doc, GeometryDocument)
    np.testing.assert_array_equal(doc.geometry.points, smoothed)
    assert doc.geometry.points.shape == ring.points.shape
    np.testing.assert_array_equal(doc.geometry.edges, ring.edges)
    phi = float(np.sum((smoothed - ring.points) ** 2))  # omega = 1
    assert phi == pytest.approx(report["phi"], rel=1e-9)
    # smoother: closer to the unit circle than the noisy input
    assert np.std(np.linalg.norm(smoothed[:, :2], axis=1)) < np.std(
        np.linalg.norm(ring.points[:, :2], axis=1)
    )
    # the result also exists in the input's format
    path = real_queue.result_file(rec.id, "obj")
    assert path is not None and path.suffix == ".obj"
    np.testing.assert_allclose(read_geometry(path).geometry.points, smoothed, atol=1e-12)


def test_mesh_job_with_rms_meets_the_implied_tau(real_queue: LocalQueue) -> None:
    sphere = noisy_sphere()
    params = SmoothingParams(rms=0.005)
    rec = real_queue.submit(NewJob.check(as_bytes(sphere, "ply"), "ply", params))
    done = wait_finished(real_queue, rec.id, timeout=60)
    assert done.status is JobStatus.SUCCEEDED, done.problem
    report = done.report
    assert report is not None and report["kind"] == "mesh"
    tau = 0.005**2 * sphere.n
    assert report["tau"] == pytest.approx(tau)
    assert abs(report["phi"] - tau) / tau <= params.tolerance
    result = real_queue.result(rec.id)
    assert result is not None and result.geometry.points.shape == (sphere.n, 3)
    np.testing.assert_array_equal(result.geometry.faces, sphere.faces)


def test_malformed_file_fails_with_a_format_problem(real_queue: LocalQueue) -> None:
    rec = real_queue.submit(NewJob.check(b"ply\nformat ascii 1.0\nelement vertex banana\n", "ply",
                            SmoothingParams(tau=1.0)))  # fmt: skip
    done = wait_finished(real_queue, rec.id, timeout=30)
    assert done.status is JobStatus.FAILED
    assert done.problem is not None and done.problem["code"] == "format-error"
    assert done.problem["field"] == "file" and "\n" not in done.problem["detail"]
    assert real_queue.result(rec.id) is None


def test_tau_out_of_range_fails_with_the_valid_range(real_queue: LocalQueue) -> None:
    cloud = Geometry(noisy_ring(50).points)  # XYZ holds points only (the ring's edges: refused)
    rec = real_queue.submit(NewJob.check(as_bytes(cloud, "xyz"), "xyz", SmoothingParams(tau=1e6)))
    done = wait_finished(real_queue, rec.id, timeout=30)
    assert done.status is JobStatus.FAILED
    problem = done.problem
    assert problem is not None and problem["code"] == "tau-out-of-range"
    assert problem["field"] == "params.tau" and problem["title"] == "Invalid parameters"
    low, high = problem["valid_range"]
    assert low == 0.0 and 0.0 < high < 1e6
