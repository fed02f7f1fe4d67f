"""``/v1/jobs``: asynchronous smoothing jobs (submit, poll, download, cancel, list)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query, Response
from fastapi.responses import FileResponse, JSONResponse
from starlette.concurrency import run_in_threadpool

from service.api.deps import JobDep, MetricsDep, QueueDep, SmoothInputDep
from service.api.docs import (
    FORMAT_QUERY_DESCRIPTION,
    JOB_SUBMIT_OPENAPI,
    MEDIA_TYPES,
    RESULT_CONTENT,
    problem_responses,
)
from service.api.problems import ApiProblem
from service.api.results import render_geometry, result_name
from service.api.schemas import Job, JobList, JobStatusName, OutputFormat, PageLinks, Report
from service.api.views import job_location, job_view
from service.jobs.queue import JobRecord, JobStatus

__all__ = ["router"]

router = APIRouter(prefix="/v1/jobs", tags=["jobs"])


@router.post(
    "",
    status_code=202,
    response_model=Job,
    response_description="Job accepted (``Location``: its status URL).",
    summary="Submit a smoothing job",
    description=(
        "Upload a geometry (``multipart/form-data``: ``file`` + ``params`` [+ ``format``]) or "
        "send it inline (``application/json``: ``{geometry, params}``). Parameters are validated "
        "and the file is parsed before the job is queued, so bad input is rejected right away "
        "(400 malformed file, 413 too large, 415 unknown format, 422 invalid parameters or "
        "geometry). Answers 202 with the job and a ``Location`` header; poll the status link."
    ),
    openapi_extra=JOB_SUBMIT_OPENAPI,
    responses=problem_responses(400, 413, 415, 422, 503),
)
async def submit_job(
    smooth_input: SmoothInputDep, queue: QueueDep, metrics: MetricsDep, response: Response
) -> Job:
    record = await run_in_threadpool(
        queue.submit,
        smooth_input.data,
        smooth_input.fmt,
        smooth_input.params,
        smooth_input.filename,
        weld=smooth_input.weld,
    )
    metrics.jobs_submitted.inc()
    response.headers["Location"] = job_location(record.id)
    return job_view(record)


@router.get(
    "",
    response_model=JobList,
    response_description="A page of jobs.",
    summary="List jobs",
    description=(
        "Jobs newest first, paged with ``offset``/``limit`` or ``page``/``size`` (``page`` "
        "wins when given), optionally filtered by status. Items leave out the reports."
    ),
    responses=problem_responses(422, 503),
)
async def list_jobs(
    queue: QueueDep,
    status: Annotated[JobStatusName | None, Query(description="Only jobs in this state.")] = None,
    offset: Annotated[int, Query(ge=0, description="Index of the first job.")] = 0,
    limit: Annotated[int, Query(ge=1, le=500, description="Jobs per page.")] = 50,
    page: Annotated[int | None, Query(ge=1, description="1-based page number.")] = None,
    size: Annotated[int | None, Query(ge=1, le=500, description="Page size with page.")] = None,
) -> JobList:
    if page is not None or size is not None:
        limit = size or limit
        offset = ((page or 1) - 1) * limit
    records, total = await run_in_threadpool(queue.list, offset, limit, status)
    query = f"&status={status}" if status else ""
    links = PageLinks(
        next=f"/v1/jobs?offset={offset + limit}&limit={limit}{query}"
        if offset + limit < total
        else None,
        prev=f"/v1/jobs?offset={max(0, offset - limit)}&limit={limit}{query}" if offset else None,
    )
    items = [job_view(r, with_report=False) for r in records]
    return JobList(items=items, total=total, offset=offset, limit=limit, links=links)


@router.get(
    "/{job_id}",
    response_model=Job,
    response_description="The job.",
    summary="Job status",
    description=(
        "The job's state. While running: ``progress`` (iteration, lambda, phi, relative error "
        "of the latest lambda iteration). Once succeeded: the full ``report``. Once failed: "
        "the problem details in ``error``."
    ),
    responses=problem_responses(404, 503),
)
async def get_job(job: JobDep) -> Job:
    return job_view(job)


def _require_succeeded(job: JobRecord) -> None:
    if job.status is JobStatus.SUCCEEDED:
        return
    if job.status in (JobStatus.QUEUED, JobStatus.RUNNING):
        raise ApiProblem(
            409,
            f"job {job.id} is {job.status.value}; poll {job_location(job.id)} until it succeeds",
            code="result-not-ready",
            title="Result not ready",
            job_status=job.status.value,
            headers={"Retry-After": "1"},
        )
    raise ApiProblem(
        409,
        f"job {job.id} is {job.status.value}; it has no result",
        code="no-result",
        title="No result",
        job_status=job.status.value,
    )


@router.get(
    "/{job_id}/result",
    summary="Download the smoothed geometry",
    description=(
        "The smoothed geometry of a succeeded job, written in ``format`` (default: the input's "
        "format), with the input's vertex count, order and connectivity. 409 while the job is "
        "queued or running (with ``Retry-After``) and for failed or cancelled jobs."
    ),
    response_class=Response,
    responses={
        200: {"description": "The smoothed geometry.", "content": RESULT_CONTENT},
        **problem_responses(404, 409, 503),
    },
)
async def get_result(
    job: JobDep,
    queue: QueueDep,
    format: Annotated[OutputFormat | None, Query(description=FORMAT_QUERY_DESCRIPTION)] = None,
) -> Response:
    _require_succeeded(job)
    fmt = format or job.fmt
    path = await run_in_threadpool(queue.result_file, job.id, fmt)
    if path is not None:  # the file the worker wrote
        name = f"{_stem(job)}.{fmt}"
        return FileResponse(path, media_type=MEDIA_TYPES[fmt], filename=name)
    document = await run_in_threadpool(queue.result, job.id)
    if document is None:  # purged or deleted meanwhile
        raise ApiProblem(404, f"the result of job {job.id} is gone", code="result-not-found")
    return await render_geometry(document, fmt, stem=_stem(job))


def _stem(job: JobRecord) -> str:
    return result_name(job.filename, job.id)


@router.get(
    "/{job_id}/report",
    response_model=Report,
    response_description="The diagnostics.",
    summary="Diagnostics of a succeeded job",
    description="Exactly ``SmoothResult.report()``: lambda, phi, tau, history, timings, ...",
    responses=problem_responses(404, 409, 503),
)
async def get_report(job: JobDep) -> JSONResponse:
    _require_succeeded(job)
    return JSONResponse(job.report or {})


@router.delete(
    "/{job_id}",
    response_model=Job,
    response_description="The cancelled job.",
    summary="Cancel or delete a job",
    description=(
        "A queued or running job is cancelled (a running solver process is stopped) and "
        "returned with status ``cancelled`` (200). A finished job is deleted with its files "
        "(204, no body)."
    ),
    responses={
        204: {"description": "The finished job and its files were deleted."},
        **problem_responses(404, 503),
    },
)
async def delete_job(job: JobDep, queue: QueueDep) -> Job | Response:
    if not job.finished:
        record = await run_in_threadpool(queue.cancel, job.id)
        if record is None:
            raise ApiProblem(404, f"no job with id {job.id!r}", code="job-not-found")
        if not record.finished:  # pragma: no cover - a queue must not leave it active
            raise ApiProblem(500, f"job {job.id} could not be cancelled", code="internal")
        if record.status is JobStatus.CANCELLED:
            return job_view(record)
        job = record  # it finished on its own meanwhile: delete it
    deleted = await run_in_threadpool(queue.delete, job.id)
    if not deleted:
        raise ApiProblem(404, f"no job with id {job.id!r}", code="job-not-found")
    return Response(status_code=204)
