"""Liveness, readiness and Prometheus metrics."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from fastapi import APIRouter, Request, Response
from prometheus_client import CONTENT_TYPE_LATEST
from pydantic import BaseModel, Field
from starlette.concurrency import run_in_threadpool

from service.api.deps import MetricsDep, SettingsDep
from service.api.docs import problem_responses
from service.api.errors import ApiProblem
from service.api.http.logs import get_logger
from service.api.intake.request import spool_dir
from service.settings import Settings

__all__ = ["Health", "Readiness", "router"]

router = APIRouter(tags=["operations"])
log = get_logger("geosmooth.api")


class Health(BaseModel):
    """Liveness answer."""

    status: str = Field(description="Always ``ok`` when the process answers.", examples=["ok"])


class Readiness(BaseModel):
    """Readiness answer."""

    status: str = Field(description="``ready``.", examples=["ready"])
    queue: bool = Field(description="The job queue is started and healthy.", examples=[True])
    checks: dict[str, str] = Field(
        description="One entry per component: ``ok`` or its condition (``storage``: ``full``, "
        "``read-only``; ``database``: ``corrupt`` ...; ``spool``: ``not-writable``).",
        examples=[{"storage": "ok", "database": "ok", "spool": "ok"}],
    )


def _writable(path: Path) -> bool:
    try:  # the spool itself may be made again, not its parents (a removed data directory)
        path.mkdir(exist_ok=True)
        fd, name = tempfile.mkstemp(prefix=".readyz-", dir=path)
        os.close(fd)
        os.unlink(name)
        return True
    except OSError:
        return False


def _readiness(request: Request, settings: Settings) -> tuple[bool, dict[str, str], str | None]:
    if not getattr(request.app.state, "queue_started", False):
        return False, {"queue": "not-started"}, "job queue not started"
    spool = "ok" if _writable(spool_dir(settings)) else "not-writable"
    try:
        health = request.app.state.queue.health()
    except Exception:
        log.exception("readyz.health_failed")
        checks, ok, detail = (
            {"queue": "health-check-failed"},
            False,
            "the queue's health check failed",
        )
    else:
        checks, ok, detail = dict(health.checks), bool(health.ok), health.detail
    checks["spool"] = spool
    if spool != "ok":
        ok, detail = False, detail or "the upload spool directory is not writable"
    return ok, checks, detail


@router.get(
    "/healthz",
    response_model=Health,
    response_description="The process is alive.",
    summary="Liveness",
    description="Answers 200 as long as the server process serves requests.",
)
async def healthz() -> Health:
    return Health(status="ok")


@router.get(
    "/readyz",
    response_model=Readiness,
    response_description="Ready to accept jobs.",
    summary="Readiness",
    description="200 when the job queue is started and its storage healthy (space left, "
    "writable, database readable) and uploads can be spooled; 503 problem details naming the "
    "failing component otherwise.",
    responses={503: problem_responses(503)[503] | {"description": "Not ready."}},
)
async def readyz(request: Request, settings: SettingsDep) -> Readiness:
    ok, checks, detail = await run_in_threadpool(_readiness, request, settings)
    if not ok:
        raise ApiProblem(
            503,
            f"not ready: {detail}",
            code="not-ready",
            queue=False,
            checks=checks,
            headers={"Retry-After": "5"},
        )
    return Readiness(status="ready", queue=True, checks=checks)


@router.get(
    "/metrics",
    summary="Prometheus metrics",
    description=(
        "Prometheus text format: ``geosmooth_jobs{status}``, ``geosmooth_queue_depth``, "
        "``geosmooth_job_solve_seconds`` (histogram), ``geosmooth_sync_solve_seconds`` "
        "(histogram), ``geosmooth_jobs_submitted_total``."
    ),
    response_class=Response,
    responses={
        200: {
            "description": "Prometheus text exposition format 0.0.4.",
            "content": {
                "text/plain": {
                    "schema": {"type": "string"},
                    "example": 'geosmooth_jobs{status="queued"} 2.0\ngeosmooth_queue_depth 2.0\n',
                }
            },
        }
    },
)
async def metrics(metrics: MetricsDep) -> Response:
    body = await run_in_threadpool(metrics.render)
    return Response(content=body, media_type=CONTENT_TYPE_LATEST)
