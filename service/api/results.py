"""Writing smoothed geometry into HTTP responses."""

from __future__ import annotations

import json
import os
import shutil
import uuid
from pathlib import Path
from typing import Any

from fastapi import Response
from starlette.concurrency import run_in_threadpool

from service.api.docs import MEDIA_TYPES
from service.io import GeometryDocument, write_geometry
from service.jobs.files import result_name

__all__ = [
    "PIN_PREFIX",
    "REPORT_HEADER",
    "REPORT_HEADER_MAX",
    "pin_file",
    "render_geometry",
    "report_header",
    "result_name",
]

REPORT_HEADER = "X-Geosmooth-Report"
REPORT_HEADER_MAX = 8192
_KEEP_HISTORY = 20
#: Spool names of pinned downloads (removed after the response; leftovers by the spool sweep).
PIN_PREFIX = "download-"


def pin_file(path: Path, spool: Path) -> Path | None:
    """A second name in ``spool`` for the result file ``path``, ``None`` if it is gone.

    A download streams the file after its headers are sent: a ``DELETE`` of the job meanwhile
    (another client, the TTL sweep) would cut the body short. A hard link keeps the data until
    the response is done (a copy where ``spool`` is on another file system).
    """
    spool.mkdir(parents=True, exist_ok=True)
    pin = spool / f"{PIN_PREFIX}{uuid.uuid4().hex}"
    try:
        try:
            os.link(path, pin)
        except FileNotFoundError:
            raise
        except OSError:  # another file system, or no hard links there
            shutil.copyfile(path, pin)
    except FileNotFoundError:
        return None
    return pin


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
