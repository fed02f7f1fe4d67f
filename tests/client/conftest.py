"""Fixtures of the client tests: a live geosmooth server (real uvicorn, loopback, free port)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tests.api.api_helpers import LiveServer


@pytest.fixture(scope="session")
def live(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    """``python -m service.api.server`` with two solver processes, for the whole session."""
    server = LiveServer(tmp_path_factory.mktemp("client") / "data", workers=2).start()
    try:
        yield server
    finally:
        server.stop()
