"""Service settings, read from the environment (prefix ``GEOSMOOTH_``).

Shared by the HTTP service, the job queue backends and their workers (so a worker needs no
``service.api`` import). Each setting is one field here: its env variable, default and bounds.
"""

from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path

from pydantic import Field
from pydantic_settings import BaseSettings, SettingsConfigDict

__all__ = ["Settings", "get_settings"]


def _default_workers() -> int:
    """One solver process per core (the issue's default)."""
    return max(1, os.cpu_count() or 1)


class Settings(BaseSettings):
    """Configuration of the HTTP service.

    Every field can be set with an environment variable ``GEOSMOOTH_<NAME>``, e.g.
    ``GEOSMOOTH_DATA_DIR=/data`` or ``GEOSMOOTH_SYNC_MAX_POINTS=50000``.
    """

    model_config = SettingsConfigDict(env_prefix="GEOSMOOTH_", extra="ignore")

    data_dir: Path = Field(
        default=Path("data"),
        description="Job store: SQLite metadata, uploaded inputs and results.",
    )
    workers: int = Field(
        default_factory=_default_workers,
        ge=1,
        le=64,
        description="Solver worker processes of the embedded queue (and concurrent sync solves).",
    )
    max_upload_bytes: int = Field(
        default=256 * 1024 * 1024,
        ge=1024,
        description="Largest request body accepted (bytes); larger requests get 413.",
    )
    max_points: int = Field(
        default=2_000_000,
        ge=1,
        description="Largest input accepted by POST /v1/jobs (points); larger inputs get 413.",
    )
    job_timeout: float = Field(
        default=3600.0, gt=0, description="Seconds a job may run before it is failed."
    )
    result_ttl: float = Field(
        default=7 * 24 * 3600.0,
        gt=0,
        description="Seconds a finished job and its files are kept before they are purged.",
    )
    sync_max_points: int = Field(
        default=20_000,
        ge=1,
        description="Largest input accepted by the synchronous POST /v1/smooth (points).",
    )

    # --- web page and job events (service/api/routers/events.py) ---
    events_poll_seconds: float = Field(
        default=0.2,
        gt=0,
        le=10,
        description="How often GET /v1/jobs/{id}/events reads the job record (seconds).",
    )
    events_ping_seconds: float = Field(
        default=15.0,
        gt=0,
        description="Interval of the keep-alive ``: ping`` comments of the events stream.",
    )


@lru_cache(maxsize=1)
def get_settings() -> Settings:
    """Settings from the environment, read once per process."""
    return Settings()
