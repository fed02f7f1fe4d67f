"""Turn job records of :mod:`service.jobs` into API representations."""

from __future__ import annotations

from typing import Any

from service.api.schemas import Job, JobLinks
from service.jobs.queue import JobRecord

__all__ = ["job_links", "job_location", "job_view"]

_PROBLEM_TYPE = "urn:geosmooth:problem:"


def job_location(job_id: str) -> str:
    """Path of the job's status resource."""
    return f"/v1/jobs/{job_id}"


def job_links(job_id: str) -> JobLinks:
    """Links to the job's status, result and report."""
    base = job_location(job_id)
    return JobLinks(status=base, result=f"{base}/result", report=f"{base}/report")


def _job_problem(problem: dict[str, Any] | None) -> dict[str, Any] | None:
    if not problem:
        return None
    out = dict(problem)
    code = out.get("code")
    out.setdefault("type", f"{_PROBLEM_TYPE}{code}" if code else "about:blank")
    out.setdefault("title", "Job failed")
    out.setdefault("detail", out.get("message") or out["title"])
    return out


def job_view(record: JobRecord, *, with_report: bool = True) -> Job:
    """The API view of a job record.

    Parameters
    ----------
    record : JobRecord
        As returned by the queue.
    with_report : bool
        Include the diagnostics of a succeeded job (left out of list pages).
    """
    data = record.to_dict()
    progress = data.get("progress") if record.status.value == "running" else None
    return Job.model_validate(
        {
            "id": data["id"],
            "status": data["status"],
            "format": data.get("format"),
            "filename": data.get("filename"),
            "created_at": data.get("created_at"),
            "started_at": data.get("started_at"),
            "finished_at": data.get("finished_at"),
            "expires_at": data.get("expires_at"),
            "attempts": data.get("attempts", 0),
            "run_seconds": data.get("run_seconds"),
            "params": data.get("params"),
            "progress": progress,
            "report": data.get("report") if with_report else None,
            "error": _job_problem(data.get("problem")),
            "links": job_links(data["id"]),
        }
    )
