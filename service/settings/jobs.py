"""The settings of the job store and the job queue (prefix ``GEOSMOOTH_``, see :class:`Settings
<service.settings.Settings>`): where jobs live, how big they may be, the queue backends, the
per-job limits and the webhooks.

One group of :class:`service.settings.Settings`; never instantiated alone (the environment
prefix is the composed class's).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Literal

from pydantic import Field, SecretStr, field_validator
from pydantic_settings import BaseSettings

__all__ = ["JobSettings"]


def _default_workers() -> int:
    """One solver process per core (the issue's default)."""
    return max(1, os.cpu_count() or 1)


class JobSettings(BaseSettings):
    """The job store, the sizes it accepts, the queue backends, limits and webhooks."""

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

    # --- checks of values whose type alone does not say enough (one line each, see
    # load_settings: the message names the variable and the forms it accepts) ---

    @field_validator("storage_url")
    @classmethod
    def _storage_url(cls, value: str | None) -> str | None:
        if value is None or not value.strip():
            return None
        if value.startswith("s3://") and value[5:].strip("/"):
            return value
        hint = (
            " (a directory is GEOSMOOTH_DATA_DIR's business: leave GEOSMOOTH_STORAGE_URL unset)"
            if "://" not in value
            else ""
        )
        raise ValueError(f"must be s3://bucket[/prefix] or unset{hint}")

    @field_validator("redis_url")
    @classmethod
    def _redis_url(cls, value: str) -> str:
        if value.startswith(("redis://", "rediss://", "unix://")):
            return value
        raise ValueError("must be redis://host:port/db, rediss://... or unix:///path.sock")

    @field_validator("data_dir")
    @classmethod
    def _data_dir(cls, value: Path) -> Path:
        if value.exists() and not value.is_dir():
            raise ValueError("must be a directory (or a path where one can be created)")
        return value
