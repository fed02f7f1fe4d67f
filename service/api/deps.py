"""FastAPI dependencies (``Annotated`` aliases used by the routers)."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Path, Request

from service.api.metrics import Metrics
from service.api.problems import ApiProblem
from service.api.uploads import SmoothInput, read_smooth_input
from service.jobs.queue import JobQueue, JobRecord
from service.settings import Settings

__all__ = [
    "JobDep",
    "MetricsDep",
    "QueueDep",
    "SettingsDep",
    "SmoothInputDep",
    "get_job",
    "get_metrics",
    "get_queue",
    "get_settings",
    "get_smooth_input",
]


async def get_settings(request: Request) -> Settings:
    """The app's settings."""
    return request.app.state.settings


async def get_queue(request: Request) -> JobQueue:
    """The app's job queue (503 until the lifespan has started it)."""
    queue = getattr(request.app.state, "queue", None)
    if queue is None or not getattr(request.app.state, "queue_started", False):
        raise ApiProblem(503, "the job queue is not running", code="queue-unavailable")
    return queue


async def get_metrics(request: Request) -> Metrics:
    """The app's Prometheus metrics."""
    return request.app.state.metrics


SettingsDep = Annotated[Settings, Depends(get_settings)]
QueueDep = Annotated[JobQueue, Depends(get_queue)]
MetricsDep = Annotated[Metrics, Depends(get_metrics)]


async def get_smooth_input(request: Request, settings: SettingsDep) -> SmoothInput:
    """The validated, parsed smoothing request (see :mod:`service.api.uploads`)."""
    return await read_smooth_input(request, settings.max_points)


SmoothInputDep = Annotated[SmoothInput, Depends(get_smooth_input)]


JobId = Annotated[
    str,
    Path(
        description="Job id, as returned by POST /v1/jobs (32 hex digits).",
        examples=["3f2a9c0d4b5e6f708192a3b4c5d6e7f8"],
    ),
]


def get_job(job_id: JobId, queue: QueueDep) -> JobRecord:
    """The job named in the path (404 problem if unknown)."""
    record = queue.get(job_id)
    if record is None:
        raise ApiProblem(404, f"no job with id {job_id!r}", code="job-not-found", field="job_id")
    return record


JobDep = Annotated[JobRecord, Depends(get_job)]
