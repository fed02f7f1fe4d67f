"""The job queue: a small protocol, the embedded local backend and the Redis/RQ backend.

See ``docs/CONTRACTS.md`` (Jobs) and ``service/jobs/README.md``. Only job ids and small
metadata travel through a queue; inputs and results live in the blob store.

This package module is the one place above the backends that names them: :func:`make_queue`
picks one from the settings (``embedded/`` and ``distributed/`` never import each other, and
the other top-level modules import neither). The backends are imported on use, so importing
``service.jobs.queue`` (the API) or the RQ worker loads no SQLite store and no Redis client.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from service.jobs.queue import FINISHED, JobQueue, JobRecord, JobSize, JobStatus, QueueHealth

if TYPE_CHECKING:
    from service.jobs.embedded.queue import LocalQueue
    from service.settings import Settings

__all__ = [
    "FINISHED",
    "JobQueue",
    "JobRecord",
    "JobSize",
    "JobStatus",
    "LocalQueue",
    "QueueHealth",
    "check_store",
    "make_queue",
]


def check_store(settings: Settings) -> None:
    """Before serving: raise :class:`~service.jobs.errors.StoreDamaged` when the embedded job
    database fails SQLite's ``quick_check`` (the RQ backend keeps no database here)."""
    if settings.queue == "rq":
        return
    from pathlib import Path

    from service.jobs.embedded.sqlite import DB_NAME, check_file

    check_file(Path(settings.data_dir) / DB_NAME)


def make_queue(settings: Settings) -> JobQueue:
    """The backend named by ``settings.queue``: ``local`` (default) or ``rq``."""
    if settings.queue == "rq":
        from service.jobs.distributed.queue import RQQueue

        return RQQueue.from_settings(settings)
    from service.jobs.embedded.queue import LocalQueue

    return LocalQueue.from_settings(settings)


def __getattr__(name: str) -> Any:
    """``service.jobs.LocalQueue``, imported on first use."""
    if name == "LocalQueue":
        from service.jobs.embedded.queue import LocalQueue

        return LocalQueue
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
