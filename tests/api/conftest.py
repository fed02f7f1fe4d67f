"""Fixtures of the HTTP tests: live servers shared by the session (plain, keyed, tight), fresh
ones on demand."""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Iterator
from pathlib import Path

import httpx
import pytest

from tests.api.api_helpers import KEYS, TIGHT_ENV, LiveServer

# Small limits so that the 413 paths are cheap to exercise.
SERVER_ENV = {
    "GEOSMOOTH_MAX_UPLOAD_BYTES": str(8 * 1024 * 1024),
    "GEOSMOOTH_SYNC_MAX_POINTS": "2000",
    "GEOSMOOTH_MAX_POINTS": "300000",
    "GEOSMOOTH_JOB_TIMEOUT": "120",
    # The slow-job fixtures are clouds of 20K-40K points: checked at submit against the
    # closed-form bound of phi(0) only, so submitting them stays fast.
    "GEOSMOOTH_SUBMIT_EXACT_TAU_POINTS": "10000",
    "GEOSMOOTH_RATE_LIMIT": "100000",  # the rate limit has its own tests
    "GEOSMOOTH_RATE_BURST": "100000",
    "GEOSMOOTH_AUTH_FAILURE_BURST": "100000",  # so is the wrong-key limit
}


@pytest.fixture(scope="session")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    """A real uvicorn server (subprocess, 127.0.0.1, free port, temp data dir, 3 workers)."""
    data_dir = tmp_path_factory.mktemp("api") / "data"
    live = LiveServer(data_dir, workers=3, env=SERVER_ENV).start()
    try:
        yield live
    finally:
        live.stop()


@pytest.fixture(scope="session")
def keyed(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    """A server with API keys (see :data:`KEYS`)."""
    root = tmp_path_factory.mktemp("keys")
    keys_file = root / "keys.txt"
    digest = hashlib.sha256(KEYS["carol"].encode()).hexdigest()
    keys_file.write_text(
        "# sha256 digest, name, bounds\n"
        f"{digest} carol max_points=100 max_k=8 rate_limit=2 rate_burst=3 "
        "max_active_jobs=1 max_upload_bytes=200000\n"
    )
    env = {
        **SERVER_ENV,
        "GEOSMOOTH_API_KEYS": f"{KEYS['alice']}, {KEYS['bob']},{KEYS['fuzz']}",
        "GEOSMOOTH_API_KEYS_FILE": str(keys_file),
    }
    live = LiveServer(root / "data", workers=2, env=env).start()
    try:
        yield live
    finally:
        live.stop()


@pytest.fixture(scope="session")
def tight(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    """A server with short timeouts, small connection bounds and CORS (see :data:`TIGHT_ENV`)."""
    root = tmp_path_factory.mktemp("tight")
    live = LiveServer(root / "data", workers=2, env={**SERVER_ENV, **TIGHT_ENV}).start()
    try:
        yield live
    finally:
        live.stop()


@pytest.fixture
def client(server: LiveServer) -> Iterator[httpx.Client]:
    with server.client() as c:
        yield c


@pytest.fixture
def make_server(tmp_path: Path) -> Iterator[Callable[..., LiveServer]]:
    """Start extra servers (stopped at the end of the test)."""
    started: list[LiveServer] = []

    def make(data_dir: Path | None = None, workers: int = 2, **env: str) -> LiveServer:
        live = LiveServer(data_dir or tmp_path / "data", workers=workers, env={**SERVER_ENV, **env})
        started.append(live)
        return live.start()

    yield make
    for live in started:
        live.stop()
