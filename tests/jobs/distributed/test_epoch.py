"""Issue 24 item 9 on a real redis-server and a live API (RQ backend): while Redis is down the
503 answers carry ``Retry-After``; a Redis restarted from its append-only file is ready again;
a Redis that came back *empty* is detected by the instance epoch and reported by ``/readyz``."""

from __future__ import annotations

import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from tests.jobs.jobs_helpers import REPO, wait_for
from tests.jobs.rq_harness import RedisServer, free_port, rq_settings, settings_env


@pytest.fixture
def api_on_redis(tmp_path: Path) -> Iterator[dict[str, Any]]:
    redis = RedisServer(tmp_path / "redis").start()
    settings = rq_settings(redis.url, tmp_path / "data", rq_queue_name="epoch")
    env = {**settings_env(settings), "GEOSMOOTH_HOST": "127.0.0.1"}
    port = free_port()
    log = open(tmp_path / "api.log", "ab")  # noqa: SIM115 (closed below)
    args = [sys.executable, "-m", "service.api.server", "--port", str(port)]
    api = subprocess.Popen(args, env=env, cwd=REPO, stdout=log, stderr=log)
    url = f"http://127.0.0.1:{port}"
    try:
        wait_for(lambda: _ready(url) == 200, timeout=90, interval=0.1)
        yield {"url": url, "redis": redis, "log": tmp_path / "api.log"}
    finally:
        api.terminate()
        try:
            api.wait(20)
        except subprocess.TimeoutExpired:
            api.kill()
        log.close()
        redis.stop()


def _ready(url: str) -> int:
    try:
        return httpx.get(f"{url}/readyz", timeout=5).status_code
    except httpx.TransportError:
        return 0


def test_redis_down_then_back_with_its_data(api_on_redis: dict[str, Any]) -> None:
    url, redis = api_on_redis["url"], api_on_redis["redis"]
    redis.kill()
    down = [httpx.get(f"{url}/v1/jobs", timeout=30), httpx.get(f"{url}/readyz", timeout=30)]
    for r in down:
        assert r.status_code == 503, r.text
        assert int(r.headers["retry-after"]) >= 1
    redis.start()  # the append-only file keeps the epoch: ready again, no alarm
    wait_for(lambda: _ready(url) == 200, timeout=60, interval=0.2)
    assert "restarted_empty" not in api_on_redis["log"].read_text()


def test_redis_back_empty_is_reported(api_on_redis: dict[str, Any]) -> None:
    url, redis = api_on_redis["url"], api_on_redis["redis"]
    redis.kill()
    shutil.rmtree(redis.dir)  # its volume is gone: Redis comes back empty
    redis.start()

    def reported() -> dict[str, Any] | None:
        r = httpx.get(f"{url}/readyz", timeout=30)
        body = r.json()
        if r.status_code == 503 and body.get("checks", {}).get("broker") == "restarted-empty":
            assert int(r.headers["retry-after"]) >= 1
            return body  # type: ignore[no-any-return]
        return None

    body = wait_for(reported, timeout=60, interval=0.2)
    assert "restarted-empty" in body["detail"]
    assert "broker.restarted_empty" in api_on_redis["log"].read_text()
