"""Issue 42 finding 2: both backends admit what the other admits.

The RQ backend's API refused horse.ply (48K vertices) with ``rms``: 413 ``ingest-time-limit``
after 108 s, where the embedded API answered 202 in 0.8 s. Its request processes came from a
forkserver without the preload and BLAS thread cap of the embedded pool, so the phi(0) check
ran 8-thread OpenBLAS under the 1 GiB address-space limit and looped in ``mmap``. Here the same
legal files with ``tau`` and ``rms`` go to an embedded and an RQ API (a real redis-server; no
RQ worker is needed to accept a job) and get the same answers.
"""

from __future__ import annotations

import json
import shutil
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from tests.api.api_helpers import LiveServer
from tests.jobs.rq_harness import RedisServer
from tests.shared_data import shared_data_dir

pytestmark = pytest.mark.skipif(shutil.which("redis-server") is None, reason="no redis-server")

FILES = ["horse.ply", "fandisk.obj", "korita-zbevnica.gpx"]


@pytest.fixture
def redis(tmp_path: Path) -> Iterator[RedisServer]:
    server = RedisServer(tmp_path / "redis").start()
    yield server
    server.stop()


def test_the_rq_api_admits_what_the_embedded_api_admits(
    make_server: Callable[..., LiveServer], redis: RedisServer, tmp_path: Path
) -> None:
    data = shared_data_dir()
    missing = [name for name in FILES if not (data / name).exists()]
    if missing:
        pytest.skip(f"shared data not found in {data}: {missing}")
    embedded = make_server(data_dir=tmp_path / "embedded")
    rq = make_server(data_dir=tmp_path / "rq", workers=None, GEOSMOOTH_QUEUE="rq",
                     GEOSMOOTH_REDIS_URL=redis.url,
                     GEOSMOOTH_RQ_QUEUE_NAME=f"admit-{uuid.uuid4().hex[:8]}")  # fmt: skip
    answers: dict[str, list[tuple[str, int, str]]] = {"embedded": [], "rq": []}
    with embedded.client() as a, rq.client() as b:
        for name in FILES:
            upload = {"file": (name, (data / name).read_bytes())}
            info = a.post("/v1/info", files=upload)
            assert info.status_code == 200, info.text
            tau_hi, rms_hi = info.json()["tau_range"][1], info.json()["rms_range"][1]
            for params in ({"rms": rms_hi / 4}, {"tau": tau_hi / 4}):
                for backend, client in (("embedded", a), ("rq", b)):
                    r = client.post("/v1/jobs", files=upload,
                                    data={"params": json.dumps(params)})  # fmt: skip
                    answers[backend].append((name, r.status_code, r.json().get("code", "")))
    assert answers["rq"] == answers["embedded"]
    assert {status for _, status, _ in answers["rq"]} == {202}, answers
