"""The job queue: a small protocol and the embedded, restart-safe local backend.

See ``docs/CONTRACTS.md``. Only job ids travel through the queue; inputs and results live in the
job store under ``data_dir``.
"""

from service.jobs.local import LocalQueue
from service.jobs.queue import FINISHED, JobQueue, JobRecord, JobStatus

__all__ = ["FINISHED", "JobQueue", "JobRecord", "JobStatus", "LocalQueue"]
