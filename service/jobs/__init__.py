"""The job queue: a small protocol, the embedded local backend and the Redis/RQ backend.

See ``docs/CONTRACTS.md`` (Jobs) and ``service/jobs/README.md``. Only job ids and small
metadata travel through a queue; inputs and results live in the blob store.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from service.jobs.embedded.queue import LocalQueue
from service.jobs.queue import FINISHED, JobQueue, JobRecord, JobSize, JobStatus, QueueHealth

if TYPE_CHECKING:
    from service.settings import Settings

__all__ = [
    "FINISHED",
    "JobQueue",
    "JobRecord",
    "JobSize",
    "JobStatus",
    "LocalQueue",
    "QueueHealth",
    "make_queue",
]


def make_queue(settings: Settings) -> JobQueue:
    """The backend named by ``settings.queue``: ``local`` (default) or ``rq``."""
    if settings.queue == "rq":
        from service.jobs.distributed.queue import RQQueue

        return RQQueue.from_settings(settings)
    return LocalQueue.from_settings(settings)
