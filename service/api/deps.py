"""FastAPI dependencies (``Annotated`` aliases used by the routers)."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Path, Request
from starlette.concurrency import run_in_threadpool

from service.api.errors import ApiProblem
from service.api.http.auth import Principal
from service.api.http.metrics import Metrics
from service.api.intake.request import Intake
from service.jobs.queue import JobQueue, JobRecord
from service.settings import Settings

__all__ = [
    "IntakeDep",
    "JobDep",
    "MetricsDep",
    "PrincipalDep",
    "QueueDep",
    "SettingsDep",
    "Tenant",
    "get_job",
    "get_principal",
    "get_queue",
    "get_settings",
    "get_tenant",
    "job_not_found",
]


async def get_settings(request: Request) -> Settings:
    """The app's settings."""
    return request.app.state.settings  # type: ignore[no-any-return]


async def get_queue(request: Request) -> JobQueue:
    """The app's job queue (503 until the lifespan has started it)."""
    queue = getattr(request.app.state, "queue", None)
    if queue is None or not getattr(request.app.state, "queue_started", False):
        raise ApiProblem(
            503,
            "the job queue is not running",
            code="queue-unavailable",
            headers={"Retry-After": "5"},
        )
    return queue  # type: ignore[no-any-return]


async def get_metrics(request: Request) -> Metrics:
    """The app's Prometheus metrics."""
    return request.app.state.metrics  # type: ignore[no-any-return]


async def get_principal(request: Request) -> Principal:
    """Who sent the request (set by :class:`service.api.http.guards.AuthGate`)."""
    principal = request.scope.get("state", {}).get("principal")
    if principal is None:  # an app mounted without its guards: nobody is trusted
        keys = request.app.state.keys
        client = request.client.host if request.client else None
        if keys.enabled:
            raise ApiProblem(401, "an API key is required", code="unauthorized")
        principal = keys.anonymous(client)
    return principal  # type: ignore[no-any-return]


PrincipalDep = Annotated[Principal, Depends(get_principal)]


async def get_tenant(principal: PrincipalDep) -> str | None:
    """The tenant owning the request's jobs (``None``: authentication is off)."""
    return principal.tenant


async def get_intake(request: Request) -> Intake:
    """The app's request intake (spooling and worker processes)."""
    return request.app.state.intake  # type: ignore[no-any-return]


SettingsDep = Annotated[Settings, Depends(get_settings)]
QueueDep = Annotated[JobQueue, Depends(get_queue)]
MetricsDep = Annotated[Metrics, Depends(get_metrics)]
IntakeDep = Annotated[Intake, Depends(get_intake)]
#: The tenant of the request (str, or None without authentication); routers of other helpers
#: (events, info) use it to scope job access.
Tenant = Annotated[str | None, Depends(get_tenant)]


JobId = Annotated[
    str,
    Path(
        description="Job id, as returned by POST /v1/jobs (32 hex digits).",
        examples=["3f2a9c0d4b5e6f708192a3b4c5d6e7f8"],
        max_length=64,
    ),
]


def job_not_found(job_id: str) -> ApiProblem:
    """The 404 of a job that is unknown *to this tenant* (another tenant's job included)."""
    return ApiProblem(404, f"no job with id {job_id!r}", code="job-not-found", field="job_id")


async def get_job(job_id: JobId, queue: QueueDep, tenant: Tenant) -> JobRecord:
    """The job named in the path, if it belongs to the tenant (404 problem otherwise)."""
    record = await run_in_threadpool(lambda: queue.get(job_id, tenant=tenant))
    if record is None:
        raise job_not_found(job_id)
    return record


JobDep = Annotated[JobRecord, Depends(get_job)]
