"""``POST /v1/smooth``: synchronous smoothing of small inputs, in a killable worker process."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

from fastapi import APIRouter, Query, Request, Response
from fastapi.responses import FileResponse
from starlette.background import BackgroundTask

from service.api.deps import IntakeDep, MetricsDep, PrincipalDep
from service.api.docs import (
    CRS_QUERY_DESCRIPTION,
    FORMAT_ALIAS_DESCRIPTION,
    FORMAT_QUERY_DESCRIPTION,
    MEDIA_TYPES,
    RESULT_CONTENT,
    SMOOTH_OPENAPI,
    problem_responses,
)
from service.api.docs import output_format as output_format_of
from service.api.intake.smoothing import smooth_input
from service.api.results import REPORT_HEADER, report_header, result_name
from service.api.schemas import OutputFormat

__all__ = ["router"]

router = APIRouter(prefix="/v1", tags=["smooth"])

_RESPONSES = {
    200: {
        "description": (
            "``format=json``: ``{geometry, report}``. Other formats: the smoothed file, with the "
            "report as compact JSON in the ``X-Geosmooth-Report`` header (spectrum left out)."
        ),
        "content": {
            **RESULT_CONTENT,
            "application/json": {
                "schema": {"$ref": "#/components/schemas/SmoothJsonResponse"},
            },
        },
        "headers": {
            REPORT_HEADER: {
                "description": "Diagnostics (SmoothResult.report() without spectrum) as compact "
                "JSON; present unless format=json.",
                "schema": {"type": "string"},
            }
        },
    },
    **problem_responses(400, 413, 415, 422, 429),
}


@router.post(
    "/smooth",
    summary="Smooth a small input synchronously",
    description=(
        "Same input as ``POST /v1/jobs`` but answered directly, for inputs of at most "
        "``sync_max_points`` points (setting ``GEOSMOOTH_SYNC_MAX_POINTS``, default 20000) that "
        "finish within ``sync_timeout`` seconds (default 60) and ``sync_memory_bytes`` of "
        "memory; anything larger gets 413: submit a job instead. The solve runs in its own "
        "process, stopped when the client disconnects. ``output_format=json`` answers "
        "``{geometry, report}``; any other format answers the file with the report in the "
        "``X-Geosmooth-Report`` header."
    ),
    response_class=Response,
    openapi_extra=SMOOTH_OPENAPI,
    responses=_RESPONSES,
)
async def smooth_now(
    request: Request,
    principal: PrincipalDep,
    intake: IntakeDep,
    metrics: MetricsDep,
    output_format: Annotated[
        OutputFormat | None, Query(description=FORMAT_QUERY_DESCRIPTION)
    ] = None,
    format: Annotated[
        OutputFormat | None, Query(description=FORMAT_ALIAS_DESCRIPTION, deprecated=True)
    ] = None,
    crs: Annotated[str | None, Query(description=CRS_QUERY_DESCRIPTION, max_length=64)] = None,
) -> Response:
    out_format = output_format_of(output_format, format)
    with intake.sync_slot(principal.bucket, principal.limits.max_sync_per_key):
        upload = await intake.receive(request)
        try:
            start = time.perf_counter()
            answer = await intake.run(
                request,
                upload,
                principal,
                smooth_input,
                mode="sync",
                out_format=out_format,
                options={"crs": crs} if crs else None,
            )
        finally:
            upload.discard()
    if answer is None:  # the client went away: nobody to answer
        return Response(status_code=499)
    metrics.sync_solve_seconds.observe(time.perf_counter() - start)
    path, fmt = Path(answer["path"]), str(answer["fmt"])
    cleanup = BackgroundTask(path.unlink, missing_ok=True)
    if fmt == "json":
        return FileResponse(path, media_type="application/json", background=cleanup)
    headers = {REPORT_HEADER: report_header(answer["report"])}
    name = f"{result_name(upload.filename, 'geometry')}.{fmt}"
    return FileResponse(
        path, media_type=MEDIA_TYPES[fmt], filename=name, headers=headers, background=cleanup
    )
