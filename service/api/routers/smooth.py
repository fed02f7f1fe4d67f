"""``POST /v1/smooth``: synchronous smoothing of small inputs."""

from __future__ import annotations

import json
import time
from typing import Annotated

import anyio
from fastapi import APIRouter, Query, Request, Response

from service.api.deps import MetricsDep, SettingsDep, SmoothInputDep
from service.api.docs import (
    FORMAT_QUERY_DESCRIPTION,
    RESULT_CONTENT,
    SMOOTH_OPENAPI,
    problem_responses,
)
from service.api.problems import ApiProblem
from service.api.results import REPORT_HEADER, render_geometry, report_header, result_name
from service.api.schemas import OutputFormat
from service.core import Geometry, SmoothingParams, SmoothResult, smooth
from service.io import write_geometry

__all__ = ["router"]

router = APIRouter(prefix="/v1", tags=["smooth"])


def _timed_smooth(geometry: Geometry, params: SmoothingParams) -> tuple[SmoothResult, float]:
    start = time.perf_counter()
    result = smooth(geometry, params)
    return result, time.perf_counter() - start


def _dumps(obj: object) -> bytes:
    return json.dumps(obj, separators=(",", ":"), allow_nan=False).encode()


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
    **problem_responses(400, 413, 415, 422),
}


@router.post(
    "/smooth",
    summary="Smooth a small input synchronously",
    description=(
        "Same input as ``POST /v1/jobs`` but answered directly, for inputs of at most "
        "``sync_max_points`` points (setting ``GEOSMOOTH_SYNC_MAX_POINTS``, default 20000; "
        "larger inputs get 413: submit a job instead). The solve runs in a worker thread, at "
        "most ``workers`` at a time. ``format=json`` answers ``{geometry, report}``; any other "
        "format answers the file with the report in the ``X-Geosmooth-Report`` header."
    ),
    response_class=Response,
    openapi_extra=SMOOTH_OPENAPI,
    responses=_RESPONSES,
)
async def smooth_now(
    request: Request,
    smooth_input: SmoothInputDep,
    settings: SettingsDep,
    metrics: MetricsDep,
    format: Annotated[OutputFormat | None, Query(description=FORMAT_QUERY_DESCRIPTION)] = None,
) -> Response:
    document = smooth_input.document
    n = document.geometry.n
    if n > settings.sync_max_points:
        raise ApiProblem(
            413,
            f"the input has {n} points; POST /v1/smooth accepts at most"
            f" {settings.sync_max_points}: submit a job to POST /v1/jobs instead",
            code="too-many-points",
            field="geometry.points",
            n_points=n,
            max_points=settings.sync_max_points,
        )
    limiter: anyio.CapacityLimiter | None = request.app.state.sync_limiter
    result, seconds = await anyio.to_thread.run_sync(
        _timed_smooth, document.geometry, smooth_input.params, limiter=limiter
    )
    metrics.sync_solve_seconds.observe(seconds)
    report = result.report()
    fmt = format or smooth_input.fmt
    if fmt == "json":
        geometry = await anyio.to_thread.run_sync(write_geometry, document, "json", result.points)
        body = b"".join([b'{"geometry":', geometry.strip(), b',"report":', _dumps(report), b"}"])
        return Response(content=body, media_type="application/json")
    return await render_geometry(
        document,
        fmt,
        stem=result_name(smooth_input.filename, "geometry"),
        points=result.points,
        headers={REPORT_HEADER: report_header(report)},
    )
