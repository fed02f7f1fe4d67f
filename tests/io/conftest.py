"""Fixtures for the io tests: the shared real-data directory and small file builders."""

from __future__ import annotations

import os
from pathlib import Path

import pytest


def shared_data_dir() -> Path | None:
    """``$GEOSMOOTH_SHARED_DATA`` or ``<repo>/../shared/data``, if it exists."""
    env = os.environ.get("GEOSMOOTH_SHARED_DATA")
    candidates = [Path(env)] if env else []
    candidates.append(Path(__file__).resolve().parents[2] / ".." / "shared" / "data")
    for path in candidates:
        if path.is_dir():
            return path.resolve()
    return None


@pytest.fixture(scope="session")
def data_dir() -> Path:
    """The shared data directory; skips the test when it is absent."""
    path = shared_data_dir()
    if path is None:
        pytest.skip("shared test data not found (set GEOSMOOTH_SHARED_DATA)")
    return path
