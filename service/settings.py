"""Service settings, read from the environment (prefix ``GEOSMOOTH_``).

Shared by the HTTP service, the job queue backends and their workers (so a worker needs no
``service.api`` import). Each setting is one field here: its env variable, default and bounds.
"""

from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path
from typing import Literal

from pydantic import Field, SecretStr
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

    # -- job queue backends, storage, limits, webhooks (service.jobs) -----------------------
    queue: Literal["local", "rq"] = Field(
        default="local",
        description="Job queue backend: the embedded SQLite queue, or Redis + RQ workers.",
    )
    redis_url: str = Field(
        default="redis://127.0.0.1:6379/0", description="Redis of the RQ backend."
    )
    rq_queue_name: str = Field(
        default="geosmooth", description="RQ queue (and Redis key prefix) of the jobs."
    )
    storage_url: str | None = Field(
        default=None,
        description="Blob store of the RQ backend: unset = the directory GEOSMOOTH_DATA_DIR "
        "(a volume shared by API and workers), or s3://bucket/prefix (endpoint and credentials "
        "from the AWS_* environment, e.g. AWS_ENDPOINT_URL_S3 for MinIO).",
    )
    presign_seconds: int = Field(
        default=0,
        ge=0,
        le=7 * 24 * 3600,
        description="S3: redirect result downloads to presigned URLs valid this long "
        "(0: the API streams results).",
    )
    max_attempts: int = Field(
        default=3,
        ge=1,
        le=20,
        description="Runs of a job whose runs are interrupted (server or worker killed).",
    )
    retry_backoff: float = Field(
        default=5.0,
        ge=0,
        description="Seconds before an interrupted job runs again (doubled per attempt).",
    )
    worker_lease: float = Field(
        default=15.0,
        gt=0,
        description="Seconds without a heartbeat after which a running job's worker is "
        "presumed dead and the job requeued.",
    )
    job_memory_limit: int | None = Field(
        default=None,
        ge=0,
        description="Per-job memory limit in bytes (refused at submit above it, enforced "
        "with RLIMIT_AS while running); unset: 80 % of RAM / workers; 0: no limit.",
    )
    threads_per_job: int | None = Field(
        default=None,
        ge=1,
        le=256,
        description="BLAS/OpenMP threads of each job process; unset: cores / workers.",
    )
    min_free_bytes: int = Field(
        default=64 * 1024 * 1024,
        ge=0,
        description="Submits are refused (507) when the job store has less free space.",
    )
    reserve_bytes: int = Field(
        default=8 * 1024 * 1024,
        ge=0,
        description="Space the embedded queue reserves (a file next to its database) to record "
        "job outcomes when the disk fills up.",
    )
    webhook_secret: SecretStr | None = Field(
        default=None, description="HMAC-SHA256 key of the Geosmooth-Signature webhook header."
    )
    webhook_allow_private: bool = Field(
        default=False,
        description="Allow webhooks to loopback, private and link-local addresses.",
    )
    webhook_timeout: float = Field(default=10.0, gt=0, description="Seconds per webhook POST.")
    webhook_max_attempts: int = Field(
        default=6, ge=1, le=20, description="Tries of a webhook delivery."
    )
    webhook_backoff: float = Field(
        default=1.0, ge=0, description="Seconds before the 2nd try (doubled per try, max 60)."
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
