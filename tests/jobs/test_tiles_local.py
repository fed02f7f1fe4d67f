"""Tiled jobs on the embedded queue: admission tiles instead of refusing, tiles on local
processes, a dead tile process re-runs its tile alone, a cancel stops the pool."""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from service.core.geometry import Geometry
from service.core.linalg.resources import estimate_resources
from service.core.params import SmoothingParams
from service.io import GeometryDocument, write_geometry
from service.jobs import JobStatus, LocalQueue
from service.jobs.limits import PARENT_BYTES_PER_POINT, auto_tile_points
from service.jobs.progress import TileCounter
from service.jobs.queue import JobSize, NewJob
from service.jobs.runner import DEFAULT_RUNNER
from service.jobs.tiles.local import local_tiles
from tests.core.tiles.terrain import terrain_cloud
from tests.jobs.jobs_helpers import pid_gone, wait_finished, wait_for

MakeQueue = Callable[..., LocalQueue]
GIB = 1 << 30


def test_auto_tile_points_fits_the_limit() -> None:
    size = JobSize(n=4_000_000, dim=3, kind="cloud")
    params = SmoothingParams()
    limit = 3 * GIB
    assert estimate_resources(size.n, 3, "cloud", params, memory_limit=limit).memory_bytes > limit
    tile = auto_tile_points(size, params, limit, workers=2)
    assert tile is not None and tile < size.n
    est = estimate_resources(2 * tile, 3, "cloud", params, memory_limit=limit // 2)
    assert PARENT_BYTES_PER_POINT * size.n + 2 * est.memory_bytes <= limit
    # the next larger tile would not fit (the largest that does is chosen)
    if 2 * tile < size.n:
        big = estimate_resources(min(4 * tile, size.n), 3, "cloud", params,
                                 memory_limit=limit // 2)  # fmt: skip
        assert PARENT_BYTES_PER_POINT * size.n + 2 * big.memory_bytes > limit
    assert auto_tile_points(size, SmoothingParams(preserve_volume=True), limit) is None


def test_submit_above_the_limit_is_tiled_not_refused(make_queue: MakeQueue) -> None:
    queue = make_queue(start=False, memory_limit=3 * GIB)
    rec = queue.submit(
        NewJob.check(b"{}", "json", SmoothingParams(), size=JobSize(4_000_000, 3, "cloud"))
    )
    assert rec.status is JobStatus.QUEUED
    assert rec.params["tile_points"] == auto_tile_points(
        JobSize(4_000_000, 3, "cloud"), SmoothingParams(), 3 * GIB, 1
    )


def _xyz(points: np.ndarray) -> bytes:
    return write_geometry(GeometryDocument.from_geometry(Geometry(points)), "xyz")


def test_tiled_job_end_to_end(make_queue: MakeQueue) -> None:
    cloud = terrain_cloud(12000, side=50.0, seed=4)
    queue = make_queue(runner=DEFAULT_RUNNER, workers=1, job_timeout=300.0)
    params = SmoothingParams(tau=60.0, tile_points=3000)
    rec = queue.submit(NewJob.check(_xyz(cloud), "xyz", params, filename="t.xyz"))
    done = wait_finished(queue, rec.id, timeout=300)
    assert done.status is JobStatus.SUCCEEDED, done.problem
    report = json.loads(queue.files.report(rec.id).read_text())
    tiles = report["tiles"]
    assert tiles["count"] == 4 and sum(t["points"] for t in tiles["tiles"]) == 12000
    assert abs(report["phi"] - 60.0) / 60.0 <= 1e-3
    smoothed = np.load(queue.files.result_points(rec.id))
    phi = float(np.sum((smoothed - cloud) ** 2))  # the xyz file rounds the input
    assert abs(phi - 60.0) / 60.0 <= 5e-3
    pids = {t["worker"] for t in tiles["tiles"]}
    assert all(w.startswith("pid ") for w in pids)


# --- the pool itself -----------------------------------------------------------------------


def _square_or_die(x: int, marker: str) -> tuple[int, int]:
    """Dies (like an out-of-memory kill) the first time it sees ``x == 3``."""
    if x == 3 and not Path(marker).exists():
        Path(marker).write_text("died once")
        os._exit(9)
    return x * x, os.getpid()


def _pid_then_sleep(x: int, where: str) -> int:
    """Writes its pid; every task but the first then sleeps for a minute."""
    Path(where, f"{x}.pid").write_text(str(os.getpid()))
    if x:
        time.sleep(60)
    return x


def test_a_dead_tile_process_reruns_its_tile(tmp_path: Path) -> None:
    counter = TileCounter()
    marker = str(tmp_path / "marker")
    with local_tiles(2, counter=counter) as run_map:
        out = run_map(_square_or_die, [(i, marker) for i in range(6)])
    assert [v for v, _ in out] == [i * i for i in range(6)]
    assert Path(marker).exists() and counter.retried >= 1
    assert counter.done == counter.total == 6


class _Cancelled(BaseException):
    pass


def test_cancel_kills_the_tile_processes(tmp_path: Path) -> None:
    def on_tile() -> None:
        wait_for(lambda: (tmp_path / "1.pid").exists() and (tmp_path / "1.pid").read_text(),
                 timeout=30)  # fmt: skip
        raise _Cancelled

    with pytest.raises(_Cancelled), local_tiles(2, on_tile) as run_map:
        run_map(_pid_then_sleep, [(0, str(tmp_path)), (1, str(tmp_path))])
    sleeper = int((tmp_path / "1.pid").read_text())
    wait_for(lambda: pid_gone(sleeper), timeout=10)
