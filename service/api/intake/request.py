"""The one path every geometry request takes: spool the body, then check it in a process.

``POST /v1/jobs``, ``POST /v1/smooth`` and ``POST /v1/info`` call :meth:`Intake.run` with the
function of :mod:`service.api.intake.smoothing` or :mod:`service.api.intake.ingest` they need.
The body is streamed to the spool directory (:mod:`service.api.intake.uploads`), then parsed
and checked in a worker process (:mod:`service.api.intake.isolation`) with

* a CPU-time limit (``parse_timeout``, at most ``ingest_timeout``; ``sync_timeout`` for
  ``POST /v1/smooth``: 413 past it), and a wall-clock safety net ten times as long (503 +
  ``Retry-After``: the server is busy); the process is killed at either and when the client
  disconnects,
* an address-space budget: ``INGEST_BASE_BYTES + INGEST_FACTOR x body`` for parsing (the io
  readers keep their peak near 3x the file), ``sync_memory_bytes`` for a synchronous solve,
* at most ``max(2, workers)`` of them at once (``workers`` solves for ``/v1/smooth``), of which
  one key (or client address) holds at most ``parse_share`` (:meth:`Intake.fair_slot`); a
  request that gets no slot within the wall-clock safety net is answered 503 + ``Retry-After``.

Inline JSON bodies are parsed with the standard library's ``json`` (about 10-15x the body in
Python objects), so they are bounded separately by ``MAX_JSON_BODY_BYTES``; larger inputs are
uploaded as files (multipart), which the io readers parse with bounded memory.
"""

from __future__ import annotations

import time
from collections.abc import AsyncIterator, Callable, Iterator
from contextlib import asynccontextmanager, contextmanager
from pathlib import Path
from typing import Any, Literal, TypeVar

import anyio
from fastapi import Request

from service.api.errors import ApiProblem
from service.api.http.auth import Principal
from service.api.intake.ingest import IngestRequest
from service.api.intake.isolation import Isolation, busy_problem, wall_limit
from service.api.intake.uploads import Upload, receive_upload
from service.settings import Settings

__all__ = [
    "INGEST_BASE_BYTES",
    "INGEST_FACTOR",
    "MAX_JSON_BODY_BYTES",
    "Intake",
    "clean_spool",
    "spool_dir",
]

INGEST_BASE_BYTES = 768 * 2**20
INGEST_FACTOR = 6
MAX_JSON_BODY_BYTES = 32 * 2**20
_SPOOL_MAX_AGE = 3600.0
T = TypeVar("T")


def spool_dir(settings: Settings) -> Path:
    """Where uploads are spooled: under ``data_dir`` so a job's input is moved, not copied."""
    return Path(settings.data_dir) / "spool"


def clean_spool(settings: Settings, max_age: float | None = None) -> int:
    """Remove spool files older than ``max_age`` seconds (left by a crash); how many.

    Default: every one when no other live server uses the spool (a crash left them: see
    :func:`service.jobs.files.sole_user`; this process registers as a user),
    else those older than an hour (another server may be receiving them).
    """
    from service.jobs.files import sole_user

    removed = 0
    now = time.time()
    directory = spool_dir(settings)
    if max_age is None:
        try:
            max_age = 0.0 if sole_user(directory) else _SPOOL_MAX_AGE
        except OSError:
            max_age = _SPOOL_MAX_AGE
    found = directory.is_dir()
    names = [*directory.glob("upload-*"), *directory.glob("download-*")] if found else []
    for path in names:  # uploads, and downloads pinned by a crashed server
        try:
            if now - path.stat().st_mtime > max_age:
                path.unlink()
                removed += 1
        except OSError:
            continue
    return removed


@asynccontextmanager
async def _acquire(limiter: anyio.CapacityLimiter, wait: float | None) -> AsyncIterator[None]:
    """Hold a token of ``limiter``; 503 ``server-busy`` when none is free within ``wait`` s."""
    got = False
    with anyio.move_on_after(wait):
        await limiter.acquire()
        got = True
    if not got:
        raise busy_problem("upload", wait or 0.0)
    try:
        yield
    finally:
        limiter.release()


class Intake:
    """Receives geometry requests for one app (see the module docstring).

    Parameters
    ----------
    settings : Settings
        Timeouts, memory budget, data directory.
    isolation : Isolation, optional
        Starts the worker processes.
    """

    def __init__(self, settings: Settings, isolation: Isolation | None = None) -> None:
        self.settings = settings
        self.isolation = isolation or Isolation()
        slots = max(2, settings.workers)
        self.ingest_limiter = anyio.CapacityLimiter(slots)
        self.sync_limiter = anyio.CapacityLimiter(settings.workers)
        self.parse_share = settings.parse_share or max(1, slots // 2)
        self._sync_active: dict[str, int] = {}
        self._shares: dict[str, anyio.CapacityLimiter] = {}

    @asynccontextmanager
    async def fair_slot(
        self, bucket: str, limiter: anyio.CapacityLimiter, wait: float | None = None
    ) -> AsyncIterator[None]:
        """A slot of ``limiter`` once ``bucket`` has fewer than its share of them in use.

        A key's uploads beyond its share wait on the key's own limiter, not in the shared
        queue, so one key's slow parses leave the other slots to the other keys. No slot after
        ``wait`` seconds: 503 ``server-busy`` + ``Retry-After`` (the server cannot take the
        work now; the request was fine).
        """
        share = self._shares.get(bucket)
        if share is None:
            share = self._shares[bucket] = anyio.CapacityLimiter(self.parse_share)
        try:
            async with _acquire(share, wait), _acquire(limiter, wait):
                yield
        finally:
            stats = share.statistics()
            if not stats.borrowed_tokens and not stats.tasks_waiting:
                self._shares.pop(bucket, None)

    @contextmanager
    def sync_slot(self, bucket: str, limit: int) -> Iterator[None]:
        """One of a key's ``limit`` concurrent synchronous solves (429 when none is free)."""
        if self._sync_active.get(bucket, 0) >= limit:
            raise ApiProblem(
                429,
                f"this key already runs {limit} synchronous solves; wait for one or submit a job",
                code="sync-quota-exceeded",
                headers={"Retry-After": "2"},
                retry_after=2,
            )
        self._sync_active[bucket] = self._sync_active.get(bucket, 0) + 1
        try:
            yield
        finally:
            self._sync_active[bucket] -= 1
            if not self._sync_active[bucket]:
                del self._sync_active[bucket]

    async def receive(self, request: Request) -> Upload:
        """Spool the request body (413 for an inline JSON body above its own bound)."""
        upload = await receive_upload(request, spool_dir(self.settings))
        if upload.kind == "json" and upload.size > MAX_JSON_BODY_BYTES:
            upload.discard()
            raise ApiProblem(
                413,
                f"an inline JSON body may have at most {MAX_JSON_BODY_BYTES} bytes; upload "
                "larger inputs as a file (multipart/form-data)",
                code="payload-too-large",
                field="body",
                max_json_body_bytes=MAX_JSON_BODY_BYTES,
            )
        return upload

    async def run(
        self,
        request: Request,
        upload: Upload,
        principal: Principal,
        func: Callable[[IngestRequest], T],
        *,
        mode: Literal["ingest", "sync"] = "ingest",
        params_required: bool = True,
        out_format: str | None = None,
        options: dict[str, Any] | None = None,
    ) -> T | None:
        """``func`` on the spooled upload in a worker process (``None``: the client left)."""
        assert upload.path is not None
        shown = upload.filename or "the upload"
        redact = {str(upload.path): shown, str(upload.path.parent): "spool"}
        redact[str(Path(self.settings.data_dir).resolve())] = "data"
        if mode == "sync":
            limiter, timeout = self.sync_limiter, self.settings.sync_timeout
            budget: int = self.settings.sync_memory_bytes
        else:
            limiter = self.ingest_limiter
            timeout = min(self.settings.ingest_timeout, self.settings.parse_timeout)
            budget = INGEST_BASE_BYTES + INGEST_FACTOR * upload.size
        req = IngestRequest(
            kind=upload.kind,
            path=str(upload.path),
            filename=upload.filename,
            part_type=upload.part_type,
            fields=dict(upload.fields),
            limits=principal.limits,
            work_dir=str(upload.path.parent),
            params_required=params_required,
            out_format=out_format,
            exact_tau_max_points=self.settings.submit_exact_tau_points,
            options={
                "dry_run_points": self.settings.submit_dry_run_points,
                "job_timeout": self.settings.job_timeout,
                # what the submit check may spend on its own analysis (half the process's
                # budget: the parsed input holds the rest)
                "check_memory_bytes": budget // 2,
                "check_seconds": timeout / 2,
                **(options or {}),
            },
        )
        async with self.fair_slot(principal.bucket, limiter, wait=wall_limit(timeout)):
            answer = await self.isolation.run(
                func,
                req,
                timeout=timeout,
                memory_bytes=budget,
                what=mode,
                redact=redact,
                disconnect=request.receive,
            )
        if answer is None and mode == "ingest":  # the client left: its parse was killed
            raise ApiProblem(400, "the client closed the request", code="client-closed-request")
        return answer
