"""Helpers for the CLI tests: run the real ``geosmooth`` command; ``data(name)``, one file of the
shared data (the ``shared_data`` fixture of ``tests/conftest.py``)."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

import pytest

from tests.shared_data import shared_data_dir

__all__ = ["REPO", "run_cli", "shared_data_dir"]  # shared_data_dir: for older imports from here

REPO = Path(__file__).resolve().parents[2]


def run_cli(
    args: Sequence[str | os.PathLike[str]],
    *,
    env: dict[str, str] | None = None,
    timeout: float = 120,
    **kwargs: object,
) -> subprocess.CompletedProcess[str]:
    """Run ``python -m service.cli ARGS`` in a subprocess (the command a user runs).

    Parameters
    ----------
    args : sequence
        Arguments after ``geosmooth``.
    env : dict, optional
        Extra environment variables.
    timeout : float
        Seconds before the test fails.

    Returns
    -------
    subprocess.CompletedProcess
        With text ``stdout`` and ``stderr`` (unless redirected through ``kwargs``).
    """
    full_env = {k: v for k, v in os.environ.items() if k != "GEOSMOOTH_DEBUG"}
    full_env.update(env or {})
    opts: dict[str, object] = {"capture_output": True, "text": True}
    opts.update(kwargs)
    if "stderr" in kwargs or "stdout" in kwargs:
        opts.pop("capture_output")
    return subprocess.run(  # type: ignore[call-overload, no-any-return]
        [sys.executable, "-m", "service.cli", *map(str, args)],
        env=full_env,
        cwd=REPO,
        timeout=timeout,
        check=False,
        **opts,
    )


@pytest.fixture(scope="session")
def cli() -> Callable[..., subprocess.CompletedProcess[str]]:
    """:func:`run_cli`, as a fixture."""
    return run_cli


@pytest.fixture(scope="session")
def data(shared_data: Path) -> Callable[[str], Path]:
    """``data(name)``: one shared data file, skipping the test if it is missing."""

    def get(name: str) -> Path:
        path = shared_data / name
        if not path.is_file():
            pytest.skip(f"{name} not in {shared_data}")
        return path

    return get
