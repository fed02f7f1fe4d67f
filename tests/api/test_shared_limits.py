"""Issue 34 (item 8, must-have 6): in the distributed deployment the rate limits live in Redis,
so API replicas share them: two live servers on one ``redis-server`` refuse together once one of
them used a key's budget (429 ``rate-limited`` + ``Retry-After``), and wrong keys sent to one
block the address on the other. The Redis buckets answer like the per-process ones.
"""

from __future__ import annotations

import asyncio
import shutil
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from service.api.http.ratelimit import MemoryBuckets, RedisBuckets
from tests.api.api_helpers import KEYS, LiveServer
from tests.jobs.rq_harness import RedisServer

pytestmark = pytest.mark.skipif(shutil.which("redis-server") is None, reason="no redis-server")


@pytest.fixture
def redis(tmp_path: Path) -> Iterator[RedisServer]:
    server = RedisServer(tmp_path / "redis").start()
    try:
        yield server
    finally:
        server.stop()


def test_redis_buckets_answer_like_the_per_process_ones(redis: RedisServer) -> None:
    """The same takes give the same answers (a slow refill: load between calls does not count)."""
    rate, burst = 0.01, 3

    async def run() -> tuple[list[float], list[float], float, float]:
        shared = RedisBuckets(redis.url, f"test-{uuid.uuid4().hex}:")
        memory = MemoryBuckets()
        try:
            waits = [await shared.take("k", rate, burst) for _ in range(5)]
            local = [await memory.take("k", rate, burst) for _ in range(5)]
            peeks = await shared.peek("k", rate, burst), await shared.peek("new", rate, burst)
            return waits, local, *peeks
        finally:
            await shared.aclose()

    waits, local, tokens, fresh = asyncio.run(run())
    assert waits[:3] == local[:3] == [0.0, 0.0, 0.0]  # the burst
    for got, want in zip(waits[3:], local[3:], strict=True):  # then a token every 1/rate s
        assert got == pytest.approx(want, abs=1.0) and 99.0 < got <= 100.0, (waits, local)
    assert tokens < 0.1 and fresh == burst


def test_an_unreachable_redis_lets_requests_through() -> None:
    from tests.jobs.rq_harness import free_port

    async def run() -> tuple[float, float]:
        gone = RedisBuckets(f"redis://127.0.0.1:{free_port()}/0", "gone:", timeout=1.0)
        return await gone.take("k", 0.01, 1), await gone.peek("k", 0.01, 1)

    assert asyncio.run(run()) == (0.0, 1.0)


def _replicas(make_server: Callable[..., LiveServer], redis: RedisServer) -> list[LiveServer]:
    env = {
        "GEOSMOOTH_QUEUE": "rq",
        "GEOSMOOTH_REDIS_URL": redis.url,
        "GEOSMOOTH_RQ_QUEUE_NAME": f"shared-{uuid.uuid4().hex[:8]}",
        "GEOSMOOTH_API_KEYS": KEYS["alice"],
        "GEOSMOOTH_RATE_LIMIT": "0.01",  # one request per 100 s after the burst
        "GEOSMOOTH_RATE_BURST": "4",
        "GEOSMOOTH_AUTH_FAILURE_BURST": "3",
        "GEOSMOOTH_AUTH_FAILURE_RATE": "0.01",
    }
    return [make_server(workers=None, **env) for _ in range(2)]


def test_two_replicas_share_one_rate_limit(
    make_server: Callable[..., LiveServer], redis: RedisServer
) -> None:
    first, second = _replicas(make_server, redis)
    alice = {"x-api-key": KEYS["alice"]}
    with first.client(**alice) as a, second.client(**alice) as b:
        assert [a.get("/v1/limits").status_code for _ in range(4)] == [200] * 4  # the burst
        refused = b.get("/v1/limits")  # the other replica: the budget is used up
        assert refused.status_code == 429, refused.text
        assert refused.headers["content-type"].startswith("application/problem+json")
        assert refused.json()["code"] == "rate-limited"
        assert 1 <= int(refused.headers["retry-after"]) <= 100
        assert a.get("/v1/limits").status_code == 429  # and the first one too
        assert b.get("/healthz").status_code == 200  # probes are not limited


def test_wrong_keys_on_one_replica_block_the_address_on_the_other(
    make_server: Callable[..., LiveServer], redis: RedisServer
) -> None:
    first, second = _replicas(make_server, redis)
    with first.client() as a, second.client() as b:
        codes = [
            a.get("/v1/jobs", headers={"authorization": f"Bearer guess-{i}"}).status_code
            for i in range(3)
        ]
        assert codes == [401] * 3
        blocked = b.get("/v1/jobs", headers={"x-api-key": KEYS["alice"]})
        assert blocked.status_code == 429, blocked.text
        assert blocked.json()["code"] == "too-many-auth-failures"
        assert 1 <= int(blocked.headers["retry-after"]) <= 100
