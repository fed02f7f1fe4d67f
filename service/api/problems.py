"""RFC 9457 problem details: the one place where errors become HTTP responses.

Every error the service answers with is ``application/problem+json``: core typed errors
(:class:`~service.core.errors.GeosmoothError`), format errors of :mod:`service.io`, parameter
validation errors (pydantic), FastAPI's own request validation errors, Starlette's HTTP errors
(404 for unknown routes, 405, 413 ...) and, as a last resort, unexpected exceptions (500, without
internals). :func:`problem_from_exception` is the single mapping; :func:`install_problem_handlers`
wires it into an app.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from http import HTTPStatus
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import ValidationError
from starlette.exceptions import HTTPException as StarletteHTTPException

from service.core.errors import GeosmoothError
from service.io import FormatError, UnsupportedFormat

__all__ = [
    "PROBLEM_MEDIA_TYPE",
    "ApiProblem",
    "InvalidInlineGeometry",
    "InvalidParams",
    "field_errors",
    "install_problem_handlers",
    "problem_from_exception",
    "problem_response",
]

PROBLEM_MEDIA_TYPE = "application/problem+json"
_TYPE_PREFIX = "urn:geosmooth:problem:"
# Members an error's to_dict() may not override (they are set from the error itself).
_RESERVED = frozenset(
    {
        "type",
        "title",
        "status",
        "detail",
        "instance",
        "code",
        "message",
        "field",
        "errors",
        "headers",
    }
)
log = logging.getLogger("geosmooth.api")


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
        """The problem object (JSON-ready)."""
        out: dict[str, Any] = {
            "type": f"{_TYPE_PREFIX}{self.code}" if self.code else "about:blank",
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
        return out


class InvalidParams(Exception):
    """The smoothing parameters of a request failed validation.

    Wraps the pydantic error, so that other pydantic errors (bugs) are not reported as the
    client's fault.
    """

    def __init__(self, error: ValidationError) -> None:
        super().__init__(str(error))
        self.error = error


class InvalidInlineGeometry(Exception):
    """The ``geometry`` member of a JSON request body does not follow the JSON schema.

    Wraps the reader's :class:`~service.io.FormatError`: inline geometry is part of the request,
    not an uploaded file, so it is a 422 on ``geometry`` rather than a 400 on ``file``.
    """

    def __init__(self, error: FormatError) -> None:
        super().__init__(str(error))
        self.error = error


def _phrase(status: int) -> str:
    try:
        return HTTPStatus(status).phrase
    except ValueError:
        return "Error"


def field_errors(
    exc: ValidationError | RequestValidationError, prefix: str
) -> list[dict[str, Any]]:
    """Flatten pydantic errors into ``{"field", "message", "type"}`` entries.

    Parameters
    ----------
    exc : ValidationError or RequestValidationError
        The validation failure.
    prefix : str
        Dotted prefix for the fields, e.g. ``"params"`` (empty: locations are used as is,
        dropping FastAPI's leading ``body`` / ``query`` / ``path``).
    """
    out: list[dict[str, Any]] = []
    for err in exc.errors():
        loc = [str(p) for p in err.get("loc", ())]
        if not prefix and loc and loc[0] in ("body", "query", "path", "header", "cookie"):
            loc = loc[1:]
        name = ".".join([prefix, *loc] if prefix else loc) or prefix or "body"
        message = str(err.get("msg", "invalid value"))
        if message.startswith("Value error, "):
            message = message[len("Value error, ") :]
        out.append({"field": name, "message": message, "type": err.get("type", "invalid")})
    return out


def problem_from_exception(exc: BaseException) -> ApiProblem:
    """Map any exception to its problem details (the single error mapping of the service).

    ============================  ======  =================================================
    exception                     status  notes
    ============================  ======  =================================================
    ApiProblem                    own     raised by the routers (404 job, 409, 413 ...)
    io.UnsupportedFormat          415     ``field="format"`` (status and title: class attributes)
    io.FormatError                400     parser message, ``field="file"``, ``line``
    core.GeosmoothError           422     ``field``, ``indices``, extras of ``to_dict()``; the
                                          class's ``status`` and ``title`` (TauOutOfRange:
                                          valid_range)
    InvalidParams                 422     SmoothingParams; ``errors`` with ``params.<name>``
    InvalidInlineGeometry         422     JSON body ``geometry`` against the schema
    RequestValidationError        422     FastAPI query/path validation
    HTTPException                 own     404 unknown route, 405, 413 ...
    anything else                 500     logged; no internals in the body
    ============================  ======  =================================================
    """
    if isinstance(exc, ApiProblem):
        return exc
    if isinstance(exc, InvalidInlineGeometry):
        message = exc.error.message
        return ApiProblem(
            422,
            message,
            code="invalid-geometry",
            title="Invalid geometry",
            field="geometry",
            errors=[{"field": "geometry", "message": message, "type": exc.error.code}],
        )
    if isinstance(exc, FormatError):  # UnsupportedFormat (415) included
        return ApiProblem(
            exc.status,
            str(exc),
            code=exc.code,
            title=exc.title,
            field="format" if isinstance(exc, UnsupportedFormat) else exc.field,
            format=None if isinstance(exc, UnsupportedFormat) else exc.fmt,
            line=exc.line,
        )
    if isinstance(exc, GeosmoothError):
        info = exc.to_dict()
        extra = {k: v for k, v in info.items() if k not in _RESERVED}
        return ApiProblem(
            exc.status,
            exc.message,
            code=exc.code,
            title=exc.title,
            field=exc.field,
            errors=[{"field": exc.field, "message": exc.message, "type": exc.code}],
            **extra,
        )
    if isinstance(exc, InvalidParams):
        errors = field_errors(exc.error, "params")
        return ApiProblem(
            422,
            "; ".join(f"{e['field']}: {e['message']}" for e in errors),
            code="invalid-parameters",
            title="Invalid parameters",
            field=errors[0]["field"] if errors else "params",
            errors=errors,
        )
    if isinstance(exc, RequestValidationError):
        errors = field_errors(exc, "")
        return ApiProblem(
            422,
            "; ".join(f"{e['field']}: {e['message']}" for e in errors),
            code="invalid-request",
            title="Invalid request",
            field=errors[0]["field"] if errors else None,
            errors=errors,
        )
    if isinstance(exc, StarletteHTTPException):
        detail = exc.detail if isinstance(exc.detail, str) else _phrase(exc.status_code)
        code = {413: "payload-too-large", 400: "malformed-request"}.get(exc.status_code)
        return ApiProblem(
            exc.status_code,
            detail,
            code=code,
            field="body" if exc.status_code == 400 else None,
            headers=exc.headers,
            max_upload_bytes=getattr(exc, "limit", None),
        )
    return ApiProblem(500, "An unexpected error occurred; it has been logged.", code="internal")


def problem_response(problem: ApiProblem, instance: str | None = None) -> JSONResponse:
    """Render a problem as an ``application/problem+json`` response."""
    return JSONResponse(
        problem.body(instance),
        status_code=problem.status,
        media_type=PROBLEM_MEDIA_TYPE,
        headers=problem.headers or None,
    )


async def _handle(request: Request, exc: Exception) -> JSONResponse:
    problem = problem_from_exception(exc)
    if problem.status >= 500:
        log.error("unhandled error on %s %s", request.method, request.url.path, exc_info=exc)
    return problem_response(problem, instance=request.url.path)


def install_problem_handlers(app: FastAPI) -> None:
    """Answer every error of ``app`` with problem details (see :func:`problem_from_exception`)."""
    for exc_type in (
        ApiProblem,
        StarletteHTTPException,
        RequestValidationError,
        InvalidParams,
        InvalidInlineGeometry,
        GeosmoothError,
        FormatError,
        Exception,
    ):
        app.add_exception_handler(exc_type, _handle)
