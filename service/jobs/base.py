"""The queue methods both backends share, written once (httpx's ``BaseClient`` pattern).

:class:`QueueBase` implements the read side of the :class:`~service.jobs.queue.JobQueue`
protocol (``get``, ``list``, ``delete``, ``result``, ``result_file``), the webhook payload, the
context-manager protocol and the store counts of ``stats`` over

* a small store protocol, :class:`RecordStore` (the SQLite and the Redis store both have it),
* four hooks a backend writes: :meth:`~QueueBase._errors` (its storage failures ->
  ``StorageFull``/``StorageUnavailable``), :meth:`~QueueBase._read_report`,
  :meth:`~QueueBase._local_file` and :meth:`~QueueBase._remove_files`.

What differs stays in the backend: ``submit`` (files + SQLite row vs blobs + Redis MULTI + RQ
job), ``cancel`` (kill a local process vs stop an RQ work horse), ``health``, the sweep.
"""

from __future__ import annotations

import builtins
import contextlib
import dataclasses
import json
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, Generic, Protocol, Self, TypeVar

from service.jobs.files import is_job_id
from service.jobs.queue import JobRecord, JobStatus

if TYPE_CHECKING:
    from service.io import GeometryDocument

__all__ = ["QueueBase", "RecordStore", "load_result", "webhook_payload", "with_report"]


class RecordStore(Protocol):
    """What :class:`QueueBase` needs of a backend's job store."""

    def get(self, job_id: str) -> JobRecord | None: ...

    def list(
        self,
        offset: int = 0,
        limit: int = 50,
        status: JobStatus | None = None,
        tenant: str | None = None,
    ) -> tuple[builtins.list[JobRecord], int]: ...

    def delete_finished(self, job_id: str) -> bool: ...

    def counts(self) -> dict[str, int]: ...


def load_result(input_path: Path, points_path: Path, fmt: str, weld: bool) -> GeometryDocument:
    """Read the input (as the job did) and put the smoothed points ``result.npy`` into it."""
    import numpy as np

    from service.io import read_geometry

    points = np.load(points_path, allow_pickle=False)
    return read_geometry(input_path, fmt, weld=weld).with_points(points)


def with_report(rec: JobRecord, read: Callable[[str], bytes | str]) -> JobRecord:
    """``rec`` with its report (``read(job_id)`` of ``report.json``) once succeeded."""
    if rec.status is not JobStatus.SUCCEEDED:
        return rec
    try:
        report = json.loads(read(rec.id))
    except FileNotFoundError:  # deleted or expired meanwhile
        return rec
    return dataclasses.replace(rec, report=report)


def webhook_payload(rec: JobRecord | None) -> tuple[str, dict[str, Any]] | None:
    """``(url, JSON of the job)`` of a job with a webhook, else ``None``."""
    if rec is None or not rec.webhook_url:
        return None
    return rec.webhook_url, rec.public_dict()


S = TypeVar("S", bound=RecordStore)


class QueueBase(Generic[S]):
    """The shared half of a job queue (module docstring); a backend subclasses it with its
    store type, e.g. ``QueueBase[JobStore]``."""

    store: S

    # -- hooks of a backend --------------------------------------------------------------
    def _errors(self) -> contextlib.AbstractContextManager[None]:
        """The backend's storage failures -> ``StorageUnavailable``/``StorageFull``."""
        raise NotImplementedError

    def _read_report(self, job_id: str) -> bytes | str:
        """The stored ``report.json`` (``FileNotFoundError`` when gone)."""
        raise NotImplementedError

    def _local_file(self, job_id: str, name: str) -> Path | None:
        """A local path of the job's file ``name`` (``None`` when it is gone)."""
        raise NotImplementedError

    def _remove_files(self, job_id: str) -> None:
        """Delete a job's files (no error if they are gone)."""
        raise NotImplementedError

    def start(self) -> None:
        raise NotImplementedError

    def stop(self) -> None:
        raise NotImplementedError

    # -- shared ----------------------------------------------------------------------------
    def __enter__(self) -> Self:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def get(self, job_id: str, *, tenant: str | None = None) -> JobRecord | None:
        """The job's record (with its report once succeeded), ``None`` if unknown."""
        if not is_job_id(job_id):
            return None
        with self._errors():
            rec = self.store.get(job_id)
        if rec is None or (tenant is not None and rec.tenant != tenant):
            return None
        return self._with_report(rec)

    def _with_report(self, rec: JobRecord) -> JobRecord:
        return with_report(rec, self._read_report)

    def list(
        self,
        offset: int = 0,
        limit: int = 50,
        status: JobStatus | str | None = None,
        *,
        tenant: str | None = None,
    ) -> tuple[builtins.list[JobRecord], int]:
        """A page of jobs, newest first (records without reports), and the total count."""
        with self._errors():
            return self.store.list(offset, limit, JobStatus(status) if status else None, tenant)

    def delete(self, job_id: str, *, tenant: str | None = None) -> bool:
        """Delete a finished job's record and files; ``False`` if unknown or not finished."""
        if self.get(job_id, tenant=tenant) is None:
            return False
        with self._errors():
            if not self.store.delete_finished(job_id):
                return False
        self._remove_files(job_id)
        return True

    def result(self, job_id: str) -> GeometryDocument | None:
        """The input document with the smoothed points (``None`` unless succeeded)."""
        rec = self.get(job_id)
        if rec is None or rec.status is not JobStatus.SUCCEEDED:
            return None
        with self._errors():
            points = self._local_file(job_id, "result.npy")
            source = self._local_file(job_id, f"input.{rec.fmt}")
        if points is None or source is None:
            return None
        try:
            return load_result(source, points, rec.fmt, rec.weld)
        except FileNotFoundError:  # deleted or expired meanwhile
            return None

    def result_file(self, job_id: str, fmt: str) -> Path | None:
        """The smoothed file the job wrote, if ``fmt`` is the input's format."""
        rec = self.get(job_id)
        if rec is None or rec.status is not JobStatus.SUCCEEDED or fmt != rec.fmt:
            return None
        with self._errors():
            return self._local_file(job_id, f"result.{fmt}")

    def _webhook_payload(self, job_id: str) -> tuple[str, dict[str, Any]] | None:
        return webhook_payload(self.get(job_id))

    def _store_counts(self) -> dict[str, Any]:
        """``counts`` (jobs per status), ``queue_depth`` and ``running`` of ``stats()``."""
        with self._errors():
            counts = self.store.counts()
        return {
            "counts": counts,
            "queue_depth": counts[JobStatus.QUEUED.value],
            "running": counts[JobStatus.RUNNING.value],
        }
