"""Issue 34 item 8 (not rate limits): a tile's keys always carry a TTL (the job may be gone:
Redis came back empty while the tile ran), every run of a tile is counted, and a worker reaps
children nobody waited for."""

from __future__ import annotations

import os
import time
from pathlib import Path

from service.jobs.distributed import tiles
from service.jobs.distributed.backend import Backend
from service.jobs.limits import reap_zombies
from tests.jobs.rq_harness import RedisServer, rq_settings

GONE = "0" * 32


def _double(x: int) -> int:
    return 2 * x


def test_a_tile_of_a_job_that_no_longer_exists_leaves_only_expiring_keys(tmp_path: Path) -> None:
    redis = RedisServer(tmp_path / "redis").start()
    try:
        backend = Backend.connect(rq_settings(redis.url, tmp_path / "data"))
        (tmp_path / "data" / "jobs" / GONE).mkdir(parents=True)
        for _ in range(2):  # run, then (its claim released) run again: both runs counted
            assert tiles._run_one(backend, GONE, "tile-r1-0", "w", (_double, (21,)))
            backend.redis.delete(tiles._key(backend, GONE, "tile-r1-0") + ":done")
        keys = backend.redis.keys("*")
        assert keys
        for key in keys:
            assert backend.redis.ttl(key) > 0, key  # nothing lives for ever
        runs = backend.redis.get(tiles._key(backend, GONE, "tile-r1-0") + ":runs")
        assert int(runs) == 2
    finally:
        redis.stop()


def test_zombie_children_are_reaped() -> None:
    pid = os.fork()
    if pid == 0:
        os._exit(0)
    deadline = time.monotonic() + 30
    reaped: list[int] = []
    while pid not in reaped and time.monotonic() < deadline:
        time.sleep(0.05)
        reaped += reap_zombies()
    assert pid in reaped
    assert not Path(f"/proc/{pid}").exists()
