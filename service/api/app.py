"""The FastAPI application factory."""

from __future__ import annotations

import json
import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

from fastapi import FastAPI
from fastapi.middleware.cors import CORSMiddleware
from starlette.concurrency import run_in_threadpool

from service.api.docs import document_common_answers
from service.api.http.auth import KeyRing
from service.api.http.context import REQUEST_ID_HEADER, RequestContextMiddleware
from service.api.http.guards import AuthGate, HostGuard, InFlightLimit, OriginGuard, allowed_hosts
from service.api.http.headers import SecurityHeaders
from service.api.http.limits import BodyLimitMiddleware
from service.api.http.metrics import Metrics
from service.api.http.ratelimit import buckets_for
from service.api.intake.request import Intake, clean_spool
from service.api.job_events import JobEventLog
from service.api.problems import PROBLEM_MEDIA_TYPE, FiniteJSONResponse, install_problem_handlers
from service.api.routers import events, health, info, jobs, smooth, web
from service.api.schemas import (
    COMPONENT_REFS,
    GEOMETRY_EXAMPLE,
    SmoothJsonRequest,
    SmoothJsonResponse,
)
from service.io import GEOMETRY_JSON_SCHEMA
from service.jobs.queue import JobQueue
from service.settings import Settings, get_settings

__all__ = ["SECURITY_SCHEMES", "create_app"]

log = logging.getLogger("geosmooth.api")

SECURITY_SCHEMES: dict[str, Any] = {
    "bearer": {"type": "http", "scheme": "bearer", "description": "Authorization: Bearer <key>"},
    "apiKey": {"type": "apiKey", "in": "header", "name": "X-API-Key"},
}

DESCRIPTION = """\
Smoothing of meshes, polylines and point clouds with a deviation budget: the smoothed points X
minimise ``||L X||^2`` subject to ``sum_i omega_i^2 ||x_i - p_i||^2 = tau`` (KU Leuven TW 451).

* ``POST /v1/jobs`` queues a job (a file upload, or the geometry inline as JSON); poll
  ``GET /v1/jobs/{id}`` or stream its ``events``, then download ``/result`` and ``/report``.
* ``POST /v1/smooth`` answers directly for small inputs.

When the server has API keys, ``/v1`` needs one (``Authorization: Bearer <key>`` or
``X-API-Key``); each key sees only its own jobs and has its own bounds and rate limit.
Every error is RFC 9457 ``application/problem+json`` with ``field`` naming the input at fault;
every answer carries ``X-Request-ID``.
"""


def _make_queue(settings: Settings) -> JobQueue:
    from service.jobs import make_queue  # imported here: export of the spec needs no queue

    return make_queue(settings)


@asynccontextmanager
async def _lifespan(app: FastAPI) -> AsyncIterator[None]:
    settings: Settings = app.state.settings
    if app.state.queue is None:
        app.state.queue = _make_queue(settings)
    queue: JobQueue = app.state.queue
    await run_in_threadpool(clean_spool, settings)
    await run_in_threadpool(queue.start)
    app.state.queue_started = True
    events = JobEventLog(queue, settings.job_log_interval)
    await run_in_threadpool(events.start)
    log.info("server.ready", extra={"workers": settings.workers, "keys": len(app.state.keys)})
    try:
        yield
    finally:
        app.state.queue_started = False
        await run_in_threadpool(events.stop)
        await run_in_threadpool(queue.stop)
        log.info("server.stopped")


def _openapi_with_extra_models(app: FastAPI) -> dict[str, Any]:
    """The spec, plus the request/response models referenced from hand-written fragments."""
    if app.openapi_schema is None:
        spec = FastAPI.openapi(app)
        schemas = spec.setdefault("components", {}).setdefault("schemas", {})
        geometry = {k: v for k, v in GEOMETRY_JSON_SCHEMA.items() if k != "$schema"}
        schemas.setdefault("GeometryJson", {**geometry, "examples": [GEOMETRY_EXAMPLE]})
        for model in (SmoothJsonRequest, SmoothJsonResponse):
            schema = model.model_json_schema(ref_template="#/components/schemas/{model}")
            for name, sub in schema.pop("$defs", {}).items():
                schemas.setdefault(name, sub)
            schemas.setdefault(model.__name__, schema)
        _link_components(schemas)
        _problems_for_validation_errors(spec)
        document_common_answers(spec)
        _document_security(spec)
        app.openapi_schema = spec
    return app.openapi_schema


def _link_components(schemas: dict[str, Any]) -> None:
    """Point pass-through dict fields at the components documenting them (COMPONENT_REFS)."""
    for (component, prop), target in COMPONENT_REFS.items():
        field = schemas.get(component, {}).get("properties", {}).get(prop)
        if field is None or target not in schemas:
            continue
        ref = {"$ref": f"#/components/schemas/{target}"}
        nullable = any(alt.get("type") == "null" for alt in field.get("anyOf", []))
        linked: dict[str, Any] = {"anyOf": [ref, {"type": "null"}]} if nullable else dict(ref)
        for key in ("title", "description", "default"):
            if key in field:
                linked[key] = field[key]
        schemas[component]["properties"][prop] = linked


def _problems_for_validation_errors(spec: dict[str, Any]) -> None:
    """Document FastAPI's automatic 422 answers as the problem details they really are."""
    problem = {"$ref": "#/components/schemas/Problem"}
    for operations in spec.get("paths", {}).values():
        for operation in operations.values():
            answer = operation.get("responses", {}).get("422")
            if answer and "HTTPValidationError" in json.dumps(answer):
                operation["responses"]["422"] = {
                    "description": "Invalid request; ``field`` / ``errors`` name the input.",
                    "content": {PROBLEM_MEDIA_TYPE: {"schema": problem}},
                }
    schemas = spec.get("components", {}).get("schemas", {})
    schemas.pop("HTTPValidationError", None)
    schemas.pop("ValidationError", None)


def _document_security(spec: dict[str, Any]) -> None:
    """API keys: optional in the spec (servers without keys accept requests without one)."""
    spec.setdefault("components", {})["securitySchemes"] = SECURITY_SCHEMES
    for path, operations in spec.get("paths", {}).items():
        if path.startswith("/v1/"):
            for operation in operations.values():
                operation["security"] = [{"bearer": []}, {"apiKey": []}, {}]


def _add_guards(app: FastAPI, settings: Settings, keys: KeyRing) -> None:
    """The middleware stack, innermost first (see :mod:`service.api.http.guards`)."""
    origins = [o.strip() for o in settings.cors_origins.split(",") if o.strip()]
    app.add_middleware(
        BodyLimitMiddleware,
        max_bytes=settings.max_upload_bytes,
        read_timeout=settings.timeout_body_read,
        min_rate=settings.body_min_rate,
        rate_window=settings.body_rate_window,
    )
    app.add_middleware(
        AuthGate,
        keys=keys,
        buckets=buckets_for(settings, "requests"),
        failure_burst=settings.auth_failure_burst,
        failure_rate=settings.auth_failure_rate,
        failures=buckets_for(settings, "auth-failures"),
    )
    app.add_middleware(OriginGuard, trusted_origins=origins)
    if origins:
        app.add_middleware(
            CORSMiddleware,
            allow_origins=origins,
            allow_methods=["GET", "POST", "DELETE"],
            allow_headers=[
                "Authorization",
                "X-API-Key",
                "Content-Type",
                "Idempotency-Key",
                REQUEST_ID_HEADER,
            ],
            expose_headers=[
                "Location",
                "Retry-After",
                REQUEST_ID_HEADER,
                "X-Geosmooth-Report",
                "Idempotent-Replayed",
            ],
            max_age=600,
        )
    app.add_middleware(HostGuard, hosts=allowed_hosts(settings.allowed_hosts, settings.host))
    app.add_middleware(InFlightLimit, limit=settings.max_requests_in_flight)
    app.add_middleware(RequestContextMiddleware)
    app.add_middleware(SecurityHeaders)


def create_app(settings: Settings | None = None, queue: JobQueue | None = None) -> FastAPI:
    """Build the geosmooth HTTP application.

    Parameters
    ----------
    settings : Settings, optional
        Default: read from the environment (``GEOSMOOTH_*``).
    queue : JobQueue, optional
        Default: a :class:`~service.jobs.embedded.queue.LocalQueue` on ``settings.data_dir``,
        created when
        the app starts. Either way the app's lifespan starts and stops the queue.

    Returns
    -------
    FastAPI
        The app; nothing is started or written until its lifespan runs.

    Raises
    ------
    ConfigError
        An invalid setting or keys file (the message names the environment variable).
    """
    settings = settings or get_settings()
    keys = KeyRing.from_settings(settings)
    app = FastAPI(
        default_response_class=FiniteJSONResponse,
        title="geosmooth",
        version="0.1.0",
        summary="Smoothing of meshes, polylines and point clouds with a deviation budget.",
        description=DESCRIPTION,
        lifespan=_lifespan,
        docs_url=None,  # /docs and /redoc: served offline by routers/web.py
        redoc_url=None,
        openapi_tags=[
            {"name": "jobs", "description": "Asynchronous smoothing jobs."},
            {"name": "smooth", "description": "Synchronous smoothing of small inputs."},
            {"name": "operations", "description": "Health, readiness and metrics."},
        ],
    )
    app.state.settings = settings
    app.state.keys = keys
    app.state.queue = queue
    app.state.queue_started = False
    app.state.metrics = Metrics(lambda: app.state.queue if app.state.queue_started else None)
    app.state.intake = Intake(settings)
    install_problem_handlers(app)
    _add_guards(app, settings, keys)
    app.include_router(jobs.router)
    app.include_router(smooth.router)
    app.include_router(health.router)
    app.include_router(events.router)
    app.include_router(info.router)
    app.include_router(web.router)
    app.openapi = lambda: _openapi_with_extra_models(app)  # type: ignore[method-assign]
    return app
