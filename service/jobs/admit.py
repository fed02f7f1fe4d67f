"""What every backend checks before it accepts a job (the shared half of ``submit``).

A :class:`~service.jobs.queue.NewJob` arrives checked (format, parameters, file, ``tau``, the
estimate and the tiles decision: the API's intake through
:func:`service.workflows.admission.check_submit`, or
:meth:`NewJob.check <service.jobs.queue.NewJob.check>`); what is left needs the queue:

* idempotency: the fingerprint of a request (:func:`request_hash`) that an ``Idempotency-Key``
  is bound to;
* the submit check's decision against the per-job memory limit (:func:`admit_size`; decided
  here only for a job that comes without one, or with one made against other limits);
* free space in the store (:func:`check_space`): a submit that would leave less than
  ``min_free_bytes`` is refused with 507 before anything is written, so running jobs keep room
  for their results and the store for its metadata.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import uuid
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from service.jobs.errors import StorageError, StorageFull, storage_error
from service.jobs.limits import _job_time_limit, tile_workers
from service.jobs.queue import JobInput, JobSize, NewJob
from service.workflows.admission import decide

if TYPE_CHECKING:
    from service.core.params import SmoothingParams

__all__ = [
    "JobRow",
    "admit",
    "admit_size",
    "check_space",
    "input_size",
    "request_hash",
    "storage_errors",
]


@dataclass(frozen=True)
class JobRow:
    """What a backend's store inserts for an admitted job (``params`` as JSON)."""

    job_id: str
    fmt: str
    filename: str | None
    params: dict[str, Any]
    input_bytes: int
    max_attempts: int
    weld: bool = False
    tenant: str | None = None
    webhook_url: str | None = None
    idempotency_key: str | None = None
    request_hash: str | None = None


def input_size(data: JobInput) -> int:
    """Bytes of the input."""
    return data.stat().st_size if isinstance(data, Path) else len(data)


def _digest(data: JobInput) -> str:
    h = hashlib.sha256()
    if isinstance(data, Path):
        with open(data, "rb") as fh:
            for block in iter(lambda: fh.read(1024 * 1024), b""):
                h.update(block)
    else:
        h.update(data)
    return h.hexdigest()


def request_hash(data: JobInput, fmt: str, params: dict[str, Any], **fields: Any) -> str:
    """Fingerprint of a submit request: the input's SHA-256 and every other member."""
    meta = json.dumps({"fmt": fmt, "params": params, **fields}, sort_keys=True)
    return hashlib.sha256(f"{_digest(data)}\n{meta}".encode()).hexdigest()


def admit_size(job: NewJob, limit: int | None) -> SmoothingParams:
    """The job's params as the submit check decided them
    (:func:`service.workflows.admission.decide`): refused
    (:class:`~service.workflows.admission.JobTooLarge`) when its memory estimate is above
    ``limit`` or its time estimate above the job time limit, with ``tile_points`` set when only
    a tiled run fits the memory limit.

    The decision the job carries (:attr:`NewJob.admission <service.jobs.queue.NewJob>`) is
    taken when it was made against this queue's limits; otherwise it is made here (reading the
    input when the job came without its ``size`` and a memory limit is set).
    """
    time_limit, workers = _job_time_limit(), tile_workers()
    carried = job.admission
    if carried is not None and carried.limits == (limit, time_limit, workers):
        return carried.accepted()  # the intake's estimate: not made again
    params = job.params
    if job.size is None and limit is None:
        return params
    size = job.size
    if size is None:
        from service.io import read_geometry

        size = JobSize.of(read_geometry(job.input, job.fmt, weld=job.weld).geometry)
    return decide(size, params, limit, time_limit, workers).accepted()


def check_space(directory: Path, needed: int, min_free: int) -> None:
    """Refuse (``StorageFull``) when ``needed`` bytes would leave less than ``min_free``."""
    try:
        st = os.statvfs(directory)
    except OSError as exc:
        raise storage_error(exc) from None  # type: ignore[misc]
    if st.f_bavail * st.f_frsize < needed + min_free:
        raise StorageFull("the job store is out of space; try again later")


@contextlib.contextmanager
def storage_errors() -> Iterator[None]:
    """Turn file-system and database failures into :class:`~service.jobs.errors.StorageFull` /
    :class:`~service.jobs.errors.StorageUnavailable` (no paths or driver text in the message)."""
    try:
        yield
    except StorageError:
        raise
    except Exception as exc:
        typed = storage_error(exc)
        if typed is None:
            raise
        raise typed from exc


def admit(job: NewJob, *, memory_limit: int | None, max_attempts: int) -> JobRow:
    """The row of an admitted job (every backend's first half of ``submit``): the request's
    fingerprint when an ``Idempotency-Key`` is given, the memory estimate.

    Raises
    ------
    JobTooLarge
        An estimate above ``memory_limit``.
    """
    stored = job.params.model_dump(mode="json", exclude_none=True)
    digest = None
    if job.idempotency_key is not None:
        digest = request_hash(job.input, job.fmt, stored, filename=job.filename, weld=job.weld,
                              webhook_url=job.webhook_url)  # fmt: skip
    stored = admit_size(job, memory_limit).model_dump(mode="json", exclude_none=True)
    return JobRow(
        uuid.uuid4().hex, job.fmt, job.filename, stored, input_size(job.input), max_attempts,
        job.weld, job.tenant, job.webhook_url, job.idempotency_key, digest,
    )  # fmt: skip
