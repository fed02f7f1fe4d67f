"""The settings of the HTTP API (prefix ``GEOSMOOTH_``, see :class:`Settings
<service.settings.Settings>`): the address, the keys and their per-key bounds, the time limits
of a request, connections, logs, the web page and the job events.

One group of :class:`service.settings.Settings`; never instantiated alone (the environment
prefix is the composed class's).
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field, SecretStr
from pydantic_settings import BaseSettings

from service.core.params import MAX_ITERATIONS_BOUND, MAX_K, SPECTRUM_MAX_POINTS

__all__ = ["HttpSettings"]


class HttpSettings(BaseSettings):
    """The HTTP API: address, keys, per-key bounds, time limits, connections, logs, events."""

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
