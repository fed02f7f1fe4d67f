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
from service.api.problems import ApiProblem

__all__ = ["Health", "Readiness", "router"]

router = APIRouter(tags=["operations"])


class Health(BaseModel):
    """Liveness answer."""

    status: str = Field(description="Always ``ok`` when the process answers.", examples=["ok"])


class Readiness(BaseModel):
    """Readiness answer."""

    status: str = Field(description="``ready``.", examples=["ready"])
    queue: bool = Field(description="The job queue is started.", examples=[True])
    data_dir_writable: bool = Field(description="The job store accepts writes.", examples=[True])


def _writable(path: Path) -> bool:
    try:
        path.mkdir(parents=True, exist_ok=True)
        fd, name = tempfile.mkstemp(prefix=".readyz-", dir=path)
        os.close(fd)
        os.unlink(name)
        return True
    except OSError:
        return False


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
    description="200 when the job queue is started and the data directory is writable, "
    "503 problem details otherwise.",
    responses={503: problem_responses(503)[503] | {"description": "Not ready."}},
)
async def readyz(request: Request, settings: SettingsDep) -> Readiness:
    queue_ok = bool(getattr(request.app.state, "queue_started", False))
    dir_ok = await run_in_threadpool(_writable, Path(settings.data_dir))
    if not (queue_ok and dir_ok):
        raise ApiProblem(
            503,
            "not ready: "
            + ", ".join(
                part
                for part, bad in (
                    ("job queue not started", not queue_ok),
                    ("data directory not writable", not dir_ok),
                )
                if bad
            ),
            code="not-ready",
            queue=queue_ok,
            data_dir_writable=dir_ok,
        )
    return Readiness(status="ready", queue=True, data_dir_writable=True)


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
