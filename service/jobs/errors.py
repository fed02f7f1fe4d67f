"""Typed errors of the job queue (raised by ``submit`` and the storage layer).

Like the core and io errors, each class carries its presentation as class attributes (``code``,
``title``, HTTP ``status``, CLI ``exit_code``) and each instance a ``field``, a one-line
``message`` and :meth:`JobsError.to_dict`; ``service.api.problems`` turns any such exception
into problem details in one generic branch, so adding a class here touches this file only.
"""

from __future__ import annotations

import errno
import sqlite3
from typing import ClassVar

from service.workflows.admission import JobTooLarge  # the submit check's refusal
from service.workflows.errors import ServiceError

__all__ = [
    "IdempotencyConflict",
    "JobTooLarge",
    "JobsError",
    "StorageError",
    "StorageFull",
    "StorageUnavailable",
    "StoreDamaged",
    "WebhookUrlRejected",
    "storage_error",
]


class JobsError(ServiceError):
    """Base class of the queue's typed errors.

    Parameters
    ----------
    message : str
        One line for humans (never a server path).
    field : str, optional
        The request member at fault (``"file"``, ``"webhook_url"``, ``"Idempotency-Key"``).
    """

    code: ClassVar[str] = "jobs-error"
    title: ClassVar[str] = "Job queue error"
    status: ClassVar[int] = 500
    exit_code: ClassVar[int] = 1  # see the CLI's table, service/exit_codes.py


class IdempotencyConflict(JobsError):
    """The idempotency key was used before with a different request."""

    code = "idempotency-conflict"
    title = "Idempotency key reused with a different request"
    status = 409
    exit_code = 2

    @classmethod
    def check(cls, stored: str | None, given: str | None, key: str) -> None:
        """Raise unless the request fingerprints of a key's two uses are equal."""
        if stored != given:
            raise cls(
                f"the idempotency key {key!r} was used for a different request",
                field="Idempotency-Key",
            )


class WebhookUrlRejected(JobsError):
    """A ``webhook_url`` that is malformed or points at a refused address (SSRF guard)."""

    code = "webhook-url-rejected"
    title = "Webhook URL rejected"
    status = 422
    exit_code = 2


class StorageError(JobsError):
    """The job store cannot take the write (base of the two storage conditions)."""


class StorageFull(StorageError):
    """No space left for the job store (HTTP 507 Insufficient Storage)."""

    code = "storage-full"
    title = "Insufficient storage"
    status = 507


class StorageUnavailable(StorageError):
    """The job store is read-only, missing, corrupted or unreachable (HTTP 503)."""

    code = "storage-unavailable"
    title = "Storage unavailable"
    status = 503


class StoreDamaged(StorageUnavailable):
    """The job database fails SQLite's integrity check, or is no database (a truncated or zeroed
    file): the server does not start on it (``geosmooth serve`` exits with its own status 14,
    ``service.api.server.StoreUnusable``)."""

    code = "store-damaged"
    title = "Job database damaged"


_FULL_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG})
_UNAVAILABLE_ERRNOS = frozenset({errno.EROFS, errno.EACCES, errno.EPERM, errno.EIO, errno.ENODEV,
                                 errno.ESTALE, errno.ENOTCONN, errno.ETIMEDOUT})  # fmt: skip


def storage_error(exc: BaseException) -> StorageError | None:
    """The storage condition an ``OSError``/``sqlite3.Error`` stands for, ``None`` otherwise.

    The message names the condition only (no paths, no driver text).
    """
    if isinstance(exc, StorageError):
        return exc
    if isinstance(exc, OSError):
        if exc.errno in _FULL_ERRNOS:
            return StorageFull("the job store is out of space")
        if exc.errno in _UNAVAILABLE_ERRNOS:
            return StorageUnavailable(f"the job store cannot be written ({_errno_name(exc)})")
        return None
    if isinstance(exc, sqlite3.OperationalError | sqlite3.DatabaseError) and not isinstance(
        exc, sqlite3.IntegrityError | sqlite3.ProgrammingError | sqlite3.InterfaceError
    ):
        text = str(exc).lower()
        if "full" in text:
            return StorageFull("the job store is out of space")
        return StorageUnavailable("the job database cannot be used")
    return None


def _errno_name(exc: OSError) -> str:
    return errno.errorcode.get(exc.errno or 0, "I/O error")
