"""The submit check (service.workflows.admission), computed once and carried by NewJob."""

from __future__ import annotations

import pickle
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from service.core import Geometry, SmoothingParams, TauOutOfRange
from service.core.errors import GeometryError
from service.jobs import admit as queue_admit
from service.jobs.errors import JobTooLarge as QueueJobTooLarge
from service.jobs.limits import _job_time_limit, tile_workers
from service.jobs.queue import NewJob
from service.workflows import admission
from service.workflows.admission import JobSize, JobTooLarge, Policy

GIB = 1024**3


def _cloud(n: int, seed: int = 0) -> Geometry:
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0.0, 10.0, (n, 2))
    return Geometry(np.c_[xy, 0.1 * np.sin(xy[:, 0]) + rng.normal(0, 0.01, n)])


def _count_estimates(monkeypatch: Any) -> list[int]:
    from service.core.linalg import resources

    calls: list[int] = []
    real = resources.estimate_resources

    def counted(*args: Any, **kwargs: Any) -> Any:
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(resources, "estimate_resources", counted)
    return calls


def test_one_estimate_for_the_whole_submit_check(monkeypatch: Any) -> None:
    calls = _count_estimates(monkeypatch)
    params = SmoothingParams(tau=0.05)
    checked = admission.check_submit(_cloud(200), params, Policy(time_limit=600.0,
                                                                 dry_run_points=500))  # fmt: skip
    assert calls == [1]  # time limit, dry run and the queue's decision share it
    assert checked.size == JobSize(n=200, dim=3, kind="cloud")
    assert checked.accepted() is params and checked.limits == (None, 600.0, 1)


def test_the_refusals_in_order(monkeypatch: Any) -> None:
    with pytest.raises(TauOutOfRange):
        admission.check_submit(_cloud(200), SmoothingParams(tau=1e9), Policy())

    def engine(error: Exception) -> Any:
        def run(*args: Any, **kwargs: Any) -> None:
            raise error

        return run

    small = Policy(dry_run_points=100)
    monkeypatch.setattr("service.workflows.smooth_file.run_engine", engine(RuntimeError("bug")))
    admission.check_submit(_cloud(50), SmoothingParams(tau=0.01), small)  # left to the job
    admission.check_submit(_cloud(150), SmoothingParams(tau=0.01), small)  # not tried
    refused = GeometryError("the points are collinear", field="geometry.points")
    monkeypatch.setattr("service.workflows.smooth_file.run_engine", engine(refused))
    with pytest.raises(GeometryError):  # the dry run: the engine's own verdict
        admission.check_submit(_cloud(50), SmoothingParams(tau=0.01), small)
    with pytest.raises(JobTooLarge) as err:  # the time estimate comes first
        admission.check_submit(_cloud(50), SmoothingParams(tau=1e9), Policy(time_limit=1e-9))
    assert err.value.to_dict()["code"] == "job-too-large" and err.value.field == "file"
    assert QueueJobTooLarge is JobTooLarge  # the queue's name for it


def test_the_queue_decision_is_recorded_not_raised() -> None:
    size = JobSize(n=4_000_000, dim=3, kind="cloud")
    params = SmoothingParams()
    tiled = admission.decide(size, params, 3 * GIB, None, 1)
    assert tiled.refusal is None
    assert tiled.accepted().tile_points == admission.auto_tile_points(size, params, 3 * GIB, 1)
    refused = admission.decide(size, SmoothingParams(preserve_volume=True), 3 * GIB, None, 1)
    assert refused.refusal is not None
    refused = pickle.loads(pickle.dumps(refused))  # it crosses the ingest process's pipe
    with pytest.raises(JobTooLarge) as err:
        refused.accepted()
    assert err.value.extra["limit_bytes"] == 3 * GIB and "GiB" in err.value.message


def test_the_queue_takes_the_carried_decision(monkeypatch: Any, tmp_path: Path) -> None:
    limit, time_limit, workers = 3 * GIB, _job_time_limit(), tile_workers()
    size = JobSize(n=4_000_000, dim=3, kind="cloud")
    carried = admission.decide(size, SmoothingParams(), limit, time_limit, workers)
    job = NewJob(b"{}", "json", SmoothingParams(), size=size, admission=carried)
    calls = _count_estimates(monkeypatch)
    assert queue_admit.admit_size(job, limit) == carried.params
    assert calls == []  # not estimated again
    other = queue_admit.admit_size(job, 2 * limit)  # decided against other limits: again
    again = admission.auto_tile_points(size, SmoothingParams(), 2 * limit, workers)
    assert calls and other.tile_points == again


def test_sync_check_only_resolves_rms() -> None:
    admission.check_sync(_cloud(100), SmoothingParams(tau=1e9))  # the engine checks the range
    with pytest.raises(TauOutOfRange):
        admission.check_sync(_cloud(100), SmoothingParams(rms=5e-324))


def _grid_mesh(side: int) -> Geometry:
    """A ``side x side`` vertex grid, two triangles per cell (a wavy sheet)."""
    u, v = np.meshgrid(np.linspace(0, 1, side), np.linspace(0, 1, side), indexing="ij")
    pts = np.c_[u.ravel(), v.ravel(), 0.05 * np.sin(8 * u.ravel()) * np.cos(8 * v.ravel())]
    idx = np.arange(side * side).reshape(side, side)
    a, b, c, d = (
        idx[:-1, :-1].ravel(),
        idx[1:, :-1].ravel(),
        idx[:-1, 1:].ravel(),
        idx[1:, 1:].ravel(),
    )
    faces = np.r_[np.c_[a, b, d], np.c_[a, d, c]]
    return Geometry(pts, faces=faces)


def _no_operator(monkeypatch: Any) -> None:
    from service.core import info

    def refuse(*args: Any, **kwargs: Any) -> Any:
        raise AssertionError("the submit check built the operator of a tiled input")

    monkeypatch.setattr(info, "valid_range", refuse)


@pytest.mark.parametrize("budget", [{"tau": 0.001}, {"rms": 0.001}, {}])
def test_a_million_vertex_mesh_with_a_budget_is_tiled_not_analysed(
    monkeypatch: Any, budget: dict[str, float]
) -> None:
    """Issue 34 item 2: a 1M-vertex mesh inside every bound, with ``tau``/``rms`` as with
    ``{}``: admitted and auto-tiled, its ``tau`` checked from the centroid bound (no operator,
    which did not fit the parse process: 413 too-large-to-process / ingest-time-limit)."""
    _no_operator(monkeypatch)
    mesh = _grid_mesh(1000)
    policy = Policy(memory_limit=GIB // 2, time_limit=3600.0, check_memory_bytes=450 * 2**20,
                    check_seconds=22.5, dry_run_points=5000)  # fmt: skip
    checked = admission.check_submit(mesh, SmoothingParams(**budget), policy)
    assert checked.refusal is None
    assert checked.accepted().tile_points, checked
    # a tau above the centroid bound is still refused at once
    with pytest.raises(TauOutOfRange):
        admission.check_submit(mesh, SmoothingParams(tau=1e12), policy)


def test_above_the_check_budget_no_operator_is_built(monkeypatch: Any) -> None:
    """An untiled input whose estimate is above the check process's budget: centroid bound."""
    _no_operator(monkeypatch)
    mesh = _grid_mesh(60)
    tight = Policy(check_memory_bytes=1, check_seconds=1e-9)
    admission.check_submit(mesh, SmoothingParams(tau=0.001), tight)
    with pytest.raises(TauOutOfRange):
        admission.check_submit(mesh, SmoothingParams(tau=1e9), tight)
    # with fixed boundary values only tau > 0 can be checked without the operator
    admission.check_submit(mesh, SmoothingParams(tau=1e9, fix_boundary=True), tight)


def test_within_the_check_budget_the_mesh_gets_the_exact_range() -> None:
    mesh = _grid_mesh(60)
    from service.core.info import valid_range

    phi0, _ = valid_range(mesh, SmoothingParams())
    roomy = Policy(check_memory_bytes=8 * GIB, check_seconds=600.0)
    with pytest.raises(TauOutOfRange):
        admission.check_submit(mesh, SmoothingParams(tau=phi0 * 1.01), roomy)
