"""Writing smoothed geometry into HTTP responses."""

from __future__ import annotations

import json
from typing import Any

from fastapi import Response
from starlette.concurrency import run_in_threadpool

from service.api.docs import MEDIA_TYPES
from service.io import GeometryDocument, write_geometry
from service.jobs.files import result_name

__all__ = [
    "REPORT_HEADER",
    "REPORT_HEADER_MAX",
    "render_geometry",
    "report_header",
    "result_name",
]

REPORT_HEADER = "X-Geosmooth-Report"
REPORT_HEADER_MAX = 8192
_KEEP_HISTORY = 20


async def render_geometry(
    document: GeometryDocument,
    fmt: str,
    *,
    stem: str,
    points: Any = None,
    headers: dict[str, str] | None = None,
) -> Response:
    """A response with ``document`` (or its geometry with ``points``) written in ``fmt``."""
    body = await run_in_threadpool(write_geometry, document, fmt, points)
    out = {"Content-Disposition": f'attachment; filename="{stem}.{fmt}"', **(headers or {})}
    return Response(content=body, media_type=MEDIA_TYPES[fmt], headers=out)


def report_header(report: dict[str, Any]) -> str:
    """The report as compact ASCII JSON for the ``X-Geosmooth-Report`` header.

    The spectrum is left out (request ``format=json`` to get it). If the header would exceed
    :data:`REPORT_HEADER_MAX` characters, only the last 20 entries of ``history`` are kept and
    ``history_omitted`` says how many were dropped.
    """
    compact = {k: v for k, v in report.items() if k != "spectrum"}
    text = json.dumps(compact, separators=(",", ":"), ensure_ascii=True, allow_nan=False)
    if len(text) > REPORT_HEADER_MAX:
        history = list(compact.get("history") or [])
        compact["history_omitted"] = max(0, len(history) - _KEEP_HISTORY)
        compact["history"] = history[-_KEEP_HISTORY:]
        text = json.dumps(compact, separators=(",", ":"), ensure_ascii=True, allow_nan=False)
    return text
