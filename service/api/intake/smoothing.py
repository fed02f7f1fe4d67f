"""``POST /v1/jobs`` and ``POST /v1/smooth`` in their request process: the one door of each into
the use cases (:mod:`service.workflows`).

A request parsed and checked by :func:`~service.api.intake.ingest.parse_request` goes to
:func:`service.workflows.admission.check_submit` (a job: estimate, ``tau``, dry run, tiles,
computed once and carried by the :class:`~service.jobs.queue.NewJob`) or to
:func:`service.workflows.smooth_file.smooth_file` (a synchronous answer).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from service.api.errors import finite
from service.api.intake.ingest import IngestRequest, parse_request
from service.jobs.queue import NewJob

__all__ = ["check_job", "smooth_input"]


def check_job(req: IngestRequest) -> NewJob:
    """``POST /v1/jobs``: the parsed, checked job (format, parameters, file, the key's bounds,
    then the submit check of :func:`service.workflows.admission.check_submit`: estimate, ``tau``,
    dry run, tiles), typed and carrying the check's
    :class:`~service.workflows.admission.Admission`; the router adds tenant and idempotency
    key. An inline geometry becomes a JSON file next to the spooled body, written once every
    check passed."""
    from service.workflows.admission import Policy, check_submit

    parsed = parse_request(req, req.limits.max_points)
    options = req.options
    policy = Policy(
        memory_limit=options.get("memory_limit"),
        time_limit=options.get("job_timeout"),
        exact_tau_max_points=req.exact_tau_max_points,
        dry_run_points=int(options.get("dry_run_points", 0)),
        tile_workers=int(options.get("tile_workers", 1)),
        check_memory_bytes=options.get("check_memory_bytes"),
        check_seconds=options.get("check_seconds"),
    )
    admission = check_submit(parsed.document.geometry, parsed.params, policy)  # 422: refused
    if "geometry" in parsed.extra:
        inline = Path(req.work_dir) / (Path(req.path).stem + ".geometry.json")
        inline.write_text(json.dumps(parsed.extra["geometry"], separators=(",", ":")))
        parsed.input_path = str(inline)
    return NewJob(
        Path(parsed.input_path), parsed.fmt, parsed.params, size=admission.size,
        filename=req.filename, weld=parsed.weld, webhook_url=parsed.webhook_url,
        admission=admission,
    )  # fmt: skip


def smooth_input(req: IngestRequest) -> dict[str, Any]:
    """``POST /v1/smooth``: the use case read -> smooth -> write
    (:func:`service.workflows.smooth_file.smooth_file`) on the parsed document, the answer
    written to a file next to the spool file."""
    from service.workflows.admission import check_sync
    from service.workflows.smooth_file import smooth_file

    parsed = parse_request(req, min(req.limits.sync_max_points, req.limits.max_points))
    fmt = req.out_format or parsed.fmt
    out = Path(req.work_dir) / (Path(req.path).stem + f".result.{fmt}")
    answer: dict[str, Any] = {"path": str(out), "fmt": fmt}

    def store(result: Any, data: bytes) -> None:
        from service.io.atomic import write_file

        report = answer["report"] = finite(result.report())
        if fmt == "json":
            text = json.dumps(report, separators=(",", ":"), allow_nan=False)
            data = b'{"geometry":' + data.strip() + b',"report":' + text.encode() + b"}"
        write_file(out, data)

    original = None if req.kind == "json" else Path(parsed.input_path)  # the upload's bytes
    crs = req.options.get("crs")  # the crs query: a projected output of geographic input
    smooth_file(parsed.document, store, parsed.params, out_fmt=fmt, original=original,
                write_options={"crs": crs} if crs else None,
                check=lambda geometry: check_sync(geometry, parsed.params))  # fmt: skip
    return {**answer, "input_fmt": parsed.fmt}
