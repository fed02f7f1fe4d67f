"""Fixtures for the io tests: the shared real-data directory (``tests/shared_data.py``)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.shared_data import shared_data_dir

__all__ = ["shared_data_dir"]  # for older imports from here


@pytest.fixture(scope="session")
def data_dir(shared_data: Path) -> Path:
    """The shared data directory (the root conftest's ``shared_data``: skips when absent)."""
    return shared_data
