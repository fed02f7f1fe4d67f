"""Problem details without a web framework: :class:`ApiProblem` and the typed-error mapping.

Kept free of FastAPI/Starlette imports so the processes that parse uploads and run
``POST /v1/smooth`` (:mod:`service.api.intake.ingest`) can turn their errors into problem details
too.

Every typed error of the project (core, io, jobs, settings) has class attributes ``status``,
``title`` and ``code`` and instance attributes ``field``, ``message`` and ``to_dict()``;
:func:`typed_problem` maps any such exception in one branch, so adding an error class never
touches the HTTP layer.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from http import HTTPStatus
from typing import Any

__all__ = [
    "PROBLEM_TYPE_PREFIX",
    "ApiProblem",
    "finite",
    "is_typed_error",
    "typed_problem",
]

PROBLEM_TYPE_PREFIX = "urn:geosmooth:problem:"
# Members an error's to_dict() may not override (they are set from the error itself).
_RESERVED = frozenset(
    {"type", "title", "status", "detail", "instance", "code", "message", "field", "errors"}
)
_HEADERS = "headers"


def finite(obj: Any) -> Any:
    """``obj`` with every non-finite float replaced by ``None`` (JSON has no NaN or inf)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, Mapping):
        return {str(k): finite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [finite(v) for v in obj]
    return obj


def _phrase(status: int) -> str:
    try:
        return HTTPStatus(status).phrase
    except ValueError:
        return "Error"


class ApiProblem(Exception):
    """An HTTP error carrying RFC 9457 problem details.

    Parameters
    ----------
    status : int
        HTTP status code.
    detail : str
        Human readable explanation specific to this occurrence.
    code : str, optional
        Machine readable problem code; the problem ``type`` is ``urn:geosmooth:problem:<code>``
        (``about:blank`` without one).
    title : str, optional
        Short summary of the problem type; default: the HTTP reason phrase.
    field : str, optional
        Dotted path of the input at fault, e.g. ``params.tau`` or ``file``.
    errors : list of dict, optional
        One entry ``{"field", "message", ...}`` per invalid input.
    headers : mapping, optional
        Extra response headers (e.g. ``Retry-After``).
    **extensions
        Further members of the problem object (e.g. ``job_id``, ``valid_range``).
    """

    def __init__(
        self,
        status: int,
        detail: str,
        *,
        code: str | None = None,
        title: str | None = None,
        field: str | None = None,
        errors: Sequence[Mapping[str, Any]] | None = None,
        headers: Mapping[str, str] | None = None,
        **extensions: Any,
    ) -> None:
        super().__init__(detail)
        self.status = status
        self.detail = detail
        self.code = code
        self.title = title or _phrase(status)
        self.field = field
        self.errors = [dict(e) for e in errors] if errors else None
        self.headers = dict(headers or {})
        self.extensions = extensions

    def body(self, instance: str | None = None) -> dict[str, Any]:
        """The problem object (JSON-ready: non-finite numbers become ``null``)."""
        out: dict[str, Any] = {
            "type": f"{PROBLEM_TYPE_PREFIX}{self.code}" if self.code else "about:blank",
            "title": self.title,
            "status": self.status,
            "detail": self.detail,
        }
        if instance:
            out["instance"] = instance
        if self.code:
            out["code"] = self.code
        if self.field:
            out["field"] = self.field
        if self.errors:
            out["errors"] = self.errors
        for key, value in self.extensions.items():
            if value is not None:
                out[key] = value
        return finite(out)  # type: ignore[no-any-return]

    def to_wire(self) -> dict[str, Any]:
        """A picklable, JSON-ready form (sent by worker processes); see :meth:`from_wire`."""
        return {"status": self.status, "headers": self.headers, "body": self.body()}

    @classmethod
    def from_wire(cls, wire: Mapping[str, Any]) -> ApiProblem:
        """The problem :meth:`to_wire` described."""
        body = dict(wire["body"])
        for key in ("type", "status", "instance"):
            body.pop(key, None)
        return cls(
            int(wire["status"]),
            str(body.pop("detail")),
            code=body.pop("code", None),
            title=body.pop("title", None),
            field=body.pop("field", None),
            errors=body.pop("errors", None),
            headers=wire.get(_HEADERS) or None,
            **body,
        )


def is_typed_error(exc: BaseException) -> bool:
    """Whether ``exc`` carries the typed-error surface (see the module docstring)."""
    cls = type(exc)
    return (
        isinstance(getattr(cls, "status", None), int)
        and isinstance(getattr(cls, "title", None), str)
        and isinstance(getattr(cls, "code", None), str)
        and hasattr(exc, "field")
        and hasattr(exc, "message")
        and callable(getattr(exc, "to_dict", None))
    )


def typed_problem(exc: BaseException) -> ApiProblem | None:
    """Problem details of a typed error (``None`` for any other exception).

    ``status``, ``title`` and ``code`` come from the class; ``field`` and ``message`` from the
    instance; the extras of ``to_dict()`` (``indices``, ``valid_range``, ``line`` ...) become
    members of the problem.
    """
    if not is_typed_error(exc):
        return None
    info: dict[str, Any] = dict(exc.to_dict())  # type: ignore[attr-defined]
    extra = {k: v for k, v in info.items() if k not in _RESERVED and k != _HEADERS}
    message = str(exc.message)  # type: ignore[attr-defined]
    field = exc.field  # type: ignore[attr-defined]
    cls = type(exc)
    errors = [{"field": field, "message": message, "type": cls.code}] if field else None  # type: ignore[attr-defined]
    headers = getattr(exc, "headers", None)
    return ApiProblem(
        cls.status,  # type: ignore[attr-defined]
        message,
        code=cls.code,  # type: ignore[attr-defined]
        title=cls.title,  # type: ignore[attr-defined]
        field=field,
        errors=errors,
        headers=headers if isinstance(headers, Mapping) else None,
        **extra,
    )
