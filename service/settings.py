"""Service settings, read from the environment (prefix ``GEOSMOOTH_``).

Shared by the HTTP service, the job queue backends and their workers (so a worker needs no
``service.api`` import). Each setting is one field here: its env variable, default and bounds.
"""

from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path
from typing import Any, ClassVar, Literal

from pydantic import Field, SecretStr, ValidationError, field_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from service.core.params import MAX_ITERATIONS_BOUND, MAX_K, SPECTRUM_MAX_POINTS

__all__ = ["ConfigError", "Settings", "default", "get_settings", "load_settings"]


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

    # --- HTTP API (service/api): address, keys, per-key bounds, connections, logs ---
    host: str = Field(
        default="127.0.0.1",
        description="Address the server binds (``geosmooth serve --host`` wins). A non-loopback "
        "address requires API keys unless ``insecure_no_auth``.",
    )
    port: int = Field(default=8000, ge=1, le=65535, description="TCP port the server binds.")
    api_keys: SecretStr | None = Field(
        default=None,
        description="API keys, comma separated (``Authorization: Bearer <key>`` or "
        "``X-API-Key``); each key is a tenant. Unset (and no keys file): no authentication.",
    )
    api_keys_file: Path | None = Field(
        default=None,
        description="File of API keys as sha256 hex digests, one per line, optionally followed "
        "by a name and per-key bounds (``max_points=5000000 rate_limit=50``).",
    )
    insecure_no_auth: bool = Field(
        default=False,
        description="Allow serving a non-loopback address without API keys (explicit opt-out).",
    )
    allowed_hosts: str = Field(
        default="",
        description="Host header allow-list, comma separated (``*``: any). Default: the bound "
        "address and localhost; any host when bound to a wildcard address (keys required).",
    )
    cors_origins: str = Field(
        default="",
        description="Origins allowed to call the API from a browser (CORS), comma separated; "
        "empty: CORS off.",
    )
    rate_limit: float = Field(
        default=20.0, gt=0, description="Requests per second per key (or client address)."
    )
    rate_burst: int = Field(default=100, ge=1, description="Requests a key may burst at once.")
    max_active_jobs: int = Field(
        default=100, ge=1, description="Queued plus running jobs per key; more get 429."
    )
    max_sync_per_key: int = Field(
        default=2, ge=1, description="Concurrent POST /v1/smooth solves per key; more get 429."
    )
    max_faces: int = Field(default=4_000_000, ge=1, description="Largest mesh (faces) accepted.")
    max_k: int = Field(default=MAX_K, ge=3, le=MAX_K, description="Largest ``params.k`` accepted.")
    max_iterations: int = Field(
        default=200,
        ge=1,
        le=MAX_ITERATIONS_BOUND,
        description="Largest ``params.max_iterations`` accepted.",
    )
    max_spectrum_points: int = Field(
        default=SPECTRUM_MAX_POINTS,
        ge=0,
        description="Largest input for which ``params.spectrum`` is accepted.",
    )
    submit_exact_tau_points: int = Field(
        default=50_000,
        ge=0,
        description="Largest point cloud whose tau is checked against the exact phi(0) at submit "
        "(larger clouds: against a closed-form upper bound; building their neighbourhoods twice "
        "would double the cost of a job).",
    )
    storage_retry_seconds: float = Field(
        default=30.0,
        gt=0,
        description="A job whose run failed for want of space (ENOSPC) is not failed: it goes "
        "back to the queue and is tried again after this many seconds, until space is back.",
    )
    submit_dry_run_points: int = Field(
        default=5000,
        ge=0,
        description="Largest input that is smoothed once at submit, so that a job the engine "
        "would refuse (too few, identical or collinear points, a budget out of range) gets 422 "
        "instead of 202 and a failed job; 0: never.",
    )
    sync_timeout: float = Field(
        default=60.0,
        gt=0,
        description="CPU seconds a POST /v1/smooth may use; then it is stopped (413). Ten times "
        "as long in wall-clock time (at least 60 s): 503 + Retry-After, the server is busy.",
    )
    sync_memory_bytes: int = Field(
        default=2 * 1024**3,
        ge=64 * 1024**2,
        description="Address space a POST /v1/smooth process may add (RLIMIT_AS).",
    )
    ingest_timeout: float = Field(
        default=600.0,
        gt=0,
        description="CPU seconds the parse and checks of an upload may use (see parse_timeout).",
    )
    parse_timeout: float = Field(
        default=45.0,
        gt=0,
        description="CPU seconds the parse and checks of one upload may use before its process "
        "is killed (413 ingest-time-limit); the effective limit is the smaller of this and "
        "ingest_timeout. CPU time, not wall time: a busy machine never makes a legal upload a "
        "413; the wall-clock safety net is ten times as long (at least 60 s) and answers 503 + "
        "Retry-After, as does an upload that waits that long for a parse slot.",
    )
    parse_share: int = Field(
        default=0,
        ge=0,
        description="Uploads one key (or client address) may have parsed at once; more wait for "
        "their key's turn without holding a slot of the others. 0: half the parse slots.",
    )
    max_connections: int = Field(
        default=2048, ge=16, description="Open connections; more are closed at once."
    )
    max_connections_per_client: int = Field(
        default=256,
        ge=1,
        description="Open connections per client address; a new one evicts that address's "
        "oldest idle connection.",
    )
    max_requests_in_flight: int = Field(
        default=512, ge=1, description="Requests handled at once; more get 503 + Retry-After."
    )
    timeout_keep_alive: float = Field(
        default=5.0, gt=0, description="Seconds an idle keep-alive connection is kept."
    )
    timeout_request_header: float = Field(
        default=10.0, gt=0, description="Seconds a client has to send a request's header."
    )
    timeout_body_read: float = Field(
        default=30.0, gt=0, description="Seconds without a byte of request body before 408."
    )
    body_min_rate: int = Field(
        default=1024,
        ge=0,
        description="Slowest upload accepted (bytes per second of waiting for the body, averaged "
        "over body_rate_window): a slower body gets 408 body-timeout and its spool file is "
        "removed, so a body of S bytes has at most body_rate_window + S / body_min_rate seconds; "
        "time the server spends elsewhere is not counted. 0: no rate bound.",
    )
    body_rate_window: float = Field(
        default=30.0,
        gt=0,
        description="Seconds over which body_min_rate is averaged: a body that falls behind it "
        "is answered within this (plus one second of grace for a busy server).",
    )
    timeout_graceful_shutdown: float = Field(
        default=10.0, gt=0, description="Seconds requests get to finish on SIGTERM."
    )
    job_log_interval: float = Field(
        default=1.0, gt=0, le=60, description="Seconds between looks for job events to log."
    )
    log_level: Literal["debug", "info", "warning", "error"] = Field(
        default="info", description="Log level."
    )
    log_format: Literal["auto", "json", "console"] = Field(
        default="auto",
        description="``json``: one JSON object per line; ``console``: text; ``auto``: on a "
        "terminal one human line with the page's and the docs' addresses, then warnings as "
        "text; elsewhere (a service manager, a container, a pipe) JSON.",
    )

    # --- web page and job events (service/api/routers/events.py) ---
    events_poll_seconds: float = Field(
        default=0.2,
        gt=0,
        le=10,
        description="How often GET /v1/jobs/{id}/events reads the job record (seconds).",
    )
    auth_failure_burst: int = Field(
        default=20,
        ge=1,
        description="Requests with a wrong API key one client address may send before its /v1 "
        "requests get 429 + Retry-After (a token bucket refilled at auth_failure_rate).",
    )
    auth_failure_rate: float = Field(
        default=0.2,
        gt=0,
        description="Wrong API keys per second a client address is allowed in the long run.",
    )
    events_max_streams: int = Field(
        default=32,
        ge=1,
        description="Event streams one key (or client address) may hold open at once; more get "
        "429 + Retry-After.",
    )
    events_ping_seconds: float = Field(
        default=15.0,
        gt=0,
        description="Interval of the keep-alive ``: ping`` comments of the events stream.",
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


def default(name: str) -> Any:
    """The default of setting ``name``: the one place a default is written (the embedded
    queue's keyword defaults and the API's documented models read it from here)."""
    return Settings.model_fields[name].get_default(call_default_factory=True)


@lru_cache(maxsize=1)
def get_settings() -> Settings:
    """Settings from the environment, read once per process (:class:`ConfigError` if invalid)."""
    return load_settings()


class ConfigError(Exception):
    """An invalid setting; the message names its environment variable (one line).

    Attributes
    ----------
    field : str
        The environment variable, e.g. ``GEOSMOOTH_WORKERS``.
    message : str
        ``GEOSMOOTH_WORKERS='abc': Input should be a valid integer ...``.
    """

    code: ClassVar[str] = "invalid-configuration"
    title: ClassVar[str] = "Invalid configuration"
    status: ClassVar[int] = 500
    exit_code: ClassVar[int] = 2  # see the CLI's table, service/exit_codes.py

    def __init__(self, message: str, *, field: str) -> None:
        super().__init__(message)
        self.message = message
        self.field = field

    def to_dict(self) -> dict[str, object]:
        """``{code, message, field}``."""
        return {"code": self.code, "message": self.message, "field": self.field}


def load_settings(**overrides: Any) -> Settings:
    """:class:`Settings` from the environment and ``overrides``.

    Raises
    ------
    ConfigError
        Naming the first invalid setting's environment variable and value.
    """
    try:
        return Settings(**overrides)
    except ValidationError as exc:
        err = exc.errors()[0]
        name = str(err["loc"][0]) if err.get("loc") else "settings"
        env = f"GEOSMOOTH_{name.upper()}"
        value = overrides.get(name, os.environ.get(env, err.get("input")))
        shown = "***" if "key" in name else repr(value)
        why = " ".join(str(err["msg"]).removeprefix("Value error, ").split())
        raise ConfigError(f"{env}={shown}: {why}", field=env) from None
