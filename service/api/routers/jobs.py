"""``/v1/jobs``: asynchronous smoothing jobs (submit, poll, download, cancel, delete, list).

Every route is scoped to the request's tenant: a job of another key is unknown (404).
"""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path
from typing import Annotated, Any

from fastapi import APIRouter, Header, Query, Request, Response
from fastapi.responses import FileResponse, RedirectResponse
from starlette.background import BackgroundTask
from starlette.concurrency import run_in_threadpool

from service.api.deps import (
    IntakeDep,
    JobDep,
    MetricsDep,
    PrincipalDep,
    QueueDep,
    SettingsDep,
    Tenant,
    job_not_found,
)
from service.api.docs import (
    CRS_QUERY_DESCRIPTION,
    FORMAT_ALIAS_DESCRIPTION,
    FORMAT_QUERY_DESCRIPTION,
    JOB_SUBMIT_OPENAPI,
    MEDIA_TYPES,
    RESULT_CONTENT,
    problem_responses,
)
from service.api.docs import output_format as output_format_of
from service.api.errors import ApiProblem
from service.api.http.logs import get_logger
from service.api.intake.request import spool_dir
from service.api.intake.smoothing import check_job
from service.api.problems import FiniteJSONResponse
from service.api.results import pin_file, render_geometry, result_name
from service.api.schemas import Job, JobList, JobStatusName, OutputFormat, PageLinks, Report
from service.jobs.limits import tile_workers
from service.jobs.queue import JobQueue, JobRecord, JobStatus, NewJob, job_location
from service.jobs.webhooks import check_webhook_url

__all__ = ["router"]

router = APIRouter(prefix="/v1/jobs", tags=["jobs"])
log = get_logger("geosmooth.api")
#: Largest offset of a job list page (SQLite integers, and no one pages further).
MAX_OFFSET = 10**9


def job_json(record: JobRecord, *, with_report: bool = True) -> dict[str, Any]:
    """The API view of a job: exactly ``record.public_dict()`` (checked against ``Job``)."""
    return record.public_dict(with_report=with_report)


async def _active_jobs(queue: JobQueue, tenant: str | None) -> int:
    def count() -> int:
        return sum(queue.list(0, 1, s, tenant=tenant)[1] for s in ("queued", "running"))

    return await run_in_threadpool(count)


IdempotencyKey = Annotated[
    str | None,
    Header(
        alias="Idempotency-Key",
        max_length=200,
        description="Retry-safe submit: the same key with the same request returns the job "
        "created first (409 if the request differs).",
    ),
]


@router.post(
    "",
    status_code=202,
    response_model=Job,
    response_description="Job accepted (``Location``: its status URL).",
    summary="Submit a smoothing job",
    description=(
        "Upload a geometry (``multipart/form-data``: ``file`` + ``params`` [+ ``format``, "
        "``weld``, ``webhook_url``]; ``params`` as a text field or a JSON file part) or send it "
        "inline (``application/json``: ``{geometry, params}``). Parameters are validated, the "
        "file is parsed and the smoothing factor is checked against ``(0, phi(0))`` before the "
        "job is queued, so bad input is rejected right away. Answers 202 with the job and a "
        "``Location`` header; poll the status link or stream its ``events``."
    ),
    openapi_extra=JOB_SUBMIT_OPENAPI,
    responses=problem_responses(400, 409, 413, 415, 422, 429, 503, 507),
)
async def submit_job(
    request: Request,
    principal: PrincipalDep,
    queue: QueueDep,
    intake: IntakeDep,
    settings: SettingsDep,
    metrics: MetricsDep,
    idempotency_key: IdempotencyKey = None,
) -> Response:
    limits = principal.limits
    if await _active_jobs(queue, principal.tenant) >= limits.max_active_jobs:
        raise ApiProblem(
            429,
            f"this key has {limits.max_active_jobs} queued or running jobs, its quota",
            code="job-quota-exceeded",
            headers={"Retry-After": "5"},
            retry_after=5,
        )
    started = time.time()
    upload = await intake.receive(request)
    job: NewJob | None = None
    try:
        own = {"memory_limit": getattr(queue, "memory_limit", None),
               "tile_workers": tile_workers()}  # the queue's limits: admission at intake
        checked = await intake.run(request, upload, principal, check_job, options=own)
        assert checked is not None
        job = replace(checked, tenant=principal.tenant, idempotency_key=idempotency_key)
        if job.webhook_url:
            await run_in_threadpool(check_webhook_url, job.webhook_url, settings)
        record = await run_in_threadpool(queue.submit, job)
    finally:
        upload.discard()
        if job is not None and isinstance(job.input, Path):
            job.input.unlink(missing_ok=True)
    replayed = record.created_at < started
    if not replayed:
        metrics.jobs_submitted.inc()
        log.info(
            "job.submitted",
            job_id=record.id,
            tenant=record.tenant,
            format=record.fmt,
            n_points=checked.size.n if checked.size else None,
        )
    headers = {"Location": job_location(record.id)}
    if replayed:
        headers["Idempotent-Replayed"] = "true"
    return FiniteJSONResponse(job_json(record), status_code=202, headers=headers)


@router.get(
    "",
    response_model=JobList,
    response_description="A page of jobs.",
    summary="List jobs",
    description=(
        "The key's jobs, newest first, paged with ``offset``/``limit`` or ``page``/``size`` "
        "(``page`` wins when given), optionally filtered by status. Items leave out reports."
    ),
    responses=problem_responses(422, 503),
)
async def list_jobs(
    queue: QueueDep,
    tenant: Tenant,
    status: Annotated[JobStatusName | None, Query(description="Only jobs in this state.")] = None,
    offset: Annotated[int, Query(ge=0, le=MAX_OFFSET, description="Index of the first job.")] = 0,
    limit: Annotated[int, Query(ge=1, le=500, description="Jobs per page.")] = 50,
    page: Annotated[
        int | None, Query(ge=1, le=MAX_OFFSET // 500, description="1-based page number.")
    ] = None,
    size: Annotated[int | None, Query(ge=1, le=500, description="Page size with page.")] = None,
) -> Response:
    if page is not None or size is not None:
        limit = size or limit
        offset = ((page or 1) - 1) * limit
    records, total = await run_in_threadpool(
        lambda: queue.list(offset, limit, status, tenant=tenant)
    )
    query = f"&status={status}" if status else ""
    links = PageLinks(
        next=f"/v1/jobs?offset={offset + limit}&limit={limit}{query}"
        if offset + limit < total
        else None,
        prev=f"/v1/jobs?offset={max(0, offset - limit)}&limit={limit}{query}" if offset else None,
    )
    items = [job_json(r, with_report=False) for r in records]
    body = {
        "items": items,
        "total": total,
        "offset": offset,
        "limit": limit,
        "links": links.model_dump(),
    }
    return FiniteJSONResponse(body)


@router.get(
    "/{job_id}",
    response_model=Job,
    response_description="The job.",
    summary="Job status",
    description=(
        "The job's state. While queued or running: ``progress`` (stage, iteration, lambda, phi, "
        "tau, percent, ETA). Once succeeded: the full ``report``. Once failed: the problem "
        "details in ``error``."
    ),
    responses=problem_responses(404, 422, 503),
)
async def get_job(job: JobDep) -> Response:
    return FiniteJSONResponse(job_json(job))


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
        "format), with the input's vertex count, order and connectivity. With an object store "
        "the answer may be a redirect (307) to a time-limited URL. 409 while the job is queued "
        "or running (with ``Retry-After``) and for failed or cancelled jobs."
    ),
    response_class=Response,
    responses={
        200: {"description": "The smoothed geometry.", "content": RESULT_CONTENT},
        307: {"description": "Redirect to a time-limited download URL of the stored result."},
        **problem_responses(404, 409, 422, 503),
    },
)
async def get_result(
    job: JobDep,
    queue: QueueDep,
    settings: SettingsDep,
    output_format: Annotated[
        OutputFormat | None, Query(description=FORMAT_QUERY_DESCRIPTION)
    ] = None,
    format: Annotated[
        OutputFormat | None, Query(description=FORMAT_ALIAS_DESCRIPTION, deprecated=True)
    ] = None,
    crs: Annotated[str | None, Query(description=CRS_QUERY_DESCRIPTION, max_length=64)] = None,
) -> Response:
    _require_succeeded(job)
    fmt = output_format_of(output_format, format) or job.fmt
    name = f"{result_name(job.filename, job.id)}.{fmt}"
    if crs:  # written for this request (the stored files are in the default frame)
        return await _result_in_crs(job, queue, fmt, crs)
    url = await run_in_threadpool(queue.result_url, job.id, fmt)
    if url is not None:
        return RedirectResponse(url, status_code=307)
    path = await run_in_threadpool(queue.result_file, job.id, fmt)
    pin = None if path is None else await run_in_threadpool(pin_file, path, spool_dir(settings))
    if pin is not None:  # streamed from its own name: a concurrent DELETE cannot cut it short
        done = BackgroundTask(pin.unlink, missing_ok=True)
        return FileResponse(pin, media_type=MEDIA_TYPES[fmt], filename=name, background=done)
    document = await run_in_threadpool(queue.result, job.id)
    if document is None:  # purged or deleted meanwhile
        raise ApiProblem(404, f"the result of job {job.id} is gone", code="result-not-found")
    return await render_geometry(document, fmt, stem=result_name(job.filename, job.id))


async def _result_in_crs(job: JobRecord, queue: JobQueue, fmt: str, crs: str) -> Response:
    """The result written in ``fmt`` with the ``crs`` option (422, field ``crs``, if refused)."""
    from service.workflows.smooth_file import encode

    document = await run_in_threadpool(queue.result, job.id)
    if document is None:
        raise ApiProblem(404, f"the result of job {job.id} is gone", code="result-not-found")
    body = await run_in_threadpool(lambda: encode(document, fmt, None, crs=crs))  # typed errors
    stem = result_name(job.filename, job.id)
    disposition = {"Content-Disposition": f'attachment; filename="{stem}.{fmt}"'}
    return Response(content=body, media_type=MEDIA_TYPES[fmt], headers=disposition)


@router.get(
    "/{job_id}/report",
    response_model=Report,
    response_description="The diagnostics.",
    summary="Diagnostics of a succeeded job",
    description="Exactly ``SmoothResult.report()``: lambda, phi, tau, history, timings, ...",
    responses=problem_responses(404, 409, 422, 503),
)
async def get_report(job: JobDep) -> Response:
    _require_succeeded(job)
    return FiniteJSONResponse(job.report or {})


@router.post(
    "/{job_id}/cancel",
    response_model=Job,
    response_description="The job after the call: ``cancelled``, or the final status it had.",
    summary="Cancel a job",
    description=(
        "A queued or running job is cancelled (a running solver process is stopped before the "
        "answer) and stays readable with status ``cancelled`` (its status and events) until it "
        "expires or is deleted. A job that already "
        "finished is returned unchanged. Idempotent: cancelling twice answers the same job."
    ),
    responses=problem_responses(404, 422, 503),
)
async def cancel_job(job: JobDep, queue: QueueDep, tenant: Tenant) -> Response:
    if job.finished:
        return FiniteJSONResponse(job_json(job))
    record = await run_in_threadpool(lambda: queue.cancel(job.id, tenant=tenant))
    if record is None:  # deleted meanwhile
        raise job_not_found(job.id)
    if record.status is JobStatus.CANCELLED:
        log.info("job.cancelled", job_id=job.id, tenant=tenant)
    return FiniteJSONResponse(job_json(record))


@router.delete(
    "/{job_id}",
    status_code=204,
    response_class=Response,
    summary="Delete a job",
    description=(
        "The job and its files are deleted (204, no body); afterwards every route of the job "
        "answers 404. A queued or running job is cancelled first (a running solver process is "
        "stopped before the answer). To stop a job and keep reading its final status, use "
        "``POST /v1/jobs/{job_id}/cancel``."
    ),
    responses={
        204: {"description": "The job and its files were deleted."},
        **problem_responses(404, 422, 503),
    },
)
async def delete_job(job: JobDep, queue: QueueDep, tenant: Tenant) -> Response:
    if not job.finished:
        record = await run_in_threadpool(lambda: queue.cancel(job.id, tenant=tenant))
        if record is None:
            raise job_not_found(job.id)
        if record.status is JobStatus.CANCELLED:
            log.info("job.cancelled", job_id=job.id, tenant=tenant)
    deleted = await run_in_threadpool(lambda: queue.delete(job.id, tenant=tenant))
    if not deleted:
        raise job_not_found(job.id)
    log.info("job.deleted", job_id=job.id, tenant=tenant)
    return Response(status_code=204)
