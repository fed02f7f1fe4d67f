"""The typed-error surface of the service layers above the engine (workflows, jobs).

Like the core and io errors, each class carries its presentation as class attributes (``code``,
``title``, HTTP ``status``, CLI ``exit_code``) and each instance a ``field``, a one-line
``message``, extra members and :meth:`ServiceError.to_dict`; ``service.api.problems`` turns any
such exception into problem details in one generic branch.
:class:`~service.workflows.admission.JobTooLarge` (the submit check's refusal) and
``service.jobs.errors.JobsError`` derive from it.
"""

from __future__ import annotations

from typing import Any, ClassVar

__all__ = ["ServiceError"]


class ServiceError(Exception):
    """Base of the typed errors above the engine.

    Parameters
    ----------
    message : str
        One line for humans (never a server path).
    field : str, optional
        The request member at fault (``"file"``, ``"webhook_url"``, ``"Idempotency-Key"``).
    **extra
        Members added to :meth:`to_dict` (limits, estimates).
    """

    code: ClassVar[str] = "service-error"
    title: ClassVar[str] = "Service error"
    status: ClassVar[int] = 500
    exit_code: ClassVar[int] = 1  # see the CLI's table, service/exit_codes.py

    def __init__(self, message: str, *, field: str | None = None, **extra: Any) -> None:
        super().__init__(message)
        self.message = message
        self.field = field
        self.extra = extra

    def to_dict(self) -> dict[str, Any]:
        """``{code, message, field?, **extra}`` (JSON-ready)."""
        out: dict[str, Any] = {"code": self.code, "message": self.message}
        if self.field is not None:
            out["field"] = self.field
        return {**out, **self.extra}
