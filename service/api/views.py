"""Turn job records of :mod:`service.jobs` into API representations."""

from __future__ import annotations

from service.api.schemas import Job
from service.jobs.queue import JobRecord, job_location

__all__ = ["job_location", "job_view"]


def job_view(record: JobRecord, *, with_report: bool = True) -> Job:
    """The API view of a job record (``record.public_dict()``, validated)."""
    return Job.model_validate(record.public_dict(with_report=with_report))
