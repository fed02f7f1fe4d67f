"""RFC 9457 problem details: the one place where errors become HTTP responses.

Every error the service answers with is ``application/problem+json``: typed errors of the
project (core, io, jobs: any exception with class attributes ``status``/``title``/``code``, see
:func:`service.api.errors.typed_problem`), parameter validation errors (pydantic), FastAPI's own
request validation errors, Starlette's HTTP errors (404 for unknown routes, 405, 413 ...) and, as
a last resort, unexpected exceptions (500, without internals). :func:`problem_from_exception` is
the single mapping; :func:`install_problem_handlers` wires it into an app (the catch-all for
unexpected exceptions is :class:`service.api.http.context.RequestContextMiddleware`, which answers
without closing the connection).
"""

from __future__ import annotations

import json
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import ValidationError
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import Match

from service.api.errors import ApiProblem, finite, typed_problem

__all__ = [
    "PROBLEM_MEDIA_TYPE",
    "ApiProblem",
    "FiniteJSONResponse",
    "InvalidInlineGeometry",
    "InvalidParams",
    "field_errors",
    "install_problem_handlers",
    "internal_problem",
    "problem_from_exception",
    "problem_response",
]

PROBLEM_MEDIA_TYPE = "application/problem+json"
_PROTOCOL_CODES = {400: "malformed-request", 413: "payload-too-large", 405: "method-not-allowed"}


class FiniteJSONResponse(JSONResponse):
    """JSON response that never fails on NaN/inf: they are written as ``null``."""

    def render(self, content: Any) -> bytes:
        try:
            text = json.dumps(content, ensure_ascii=False, allow_nan=False, separators=(",", ":"))
        except ValueError:  # a non-finite float somewhere: never a 500 for that
            text = json.dumps(finite(content), ensure_ascii=False, separators=(",", ":"))
        return text.encode("utf-8")


class InvalidParams(Exception):
    """The smoothing parameters of a request failed validation.

    Wraps the pydantic error, so that other pydantic errors (bugs) are not reported as the
    client's fault.
    """

    def __init__(self, error: ValidationError) -> None:
        super().__init__(str(error))
        self.error = error


class InvalidInlineGeometry(Exception):
    """The ``geometry`` member of a JSON request body does not follow the JSON schema."""

    def __init__(self, message: str, code: str = "format-error") -> None:
        super().__init__(message)
        self.message = message
        self.code = code


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


def _validation(
    errors: list[dict[str, Any]], code: str, title: str, default: str | None
) -> ApiProblem:
    return ApiProblem(
        422,
        "; ".join(f"{e['field']}: {e['message']}" for e in errors),
        code=code,
        title=title,
        field=errors[0]["field"] if errors else default,
        errors=errors,
    )


def internal_problem() -> ApiProblem:
    """The answer to an unexpected exception: no internals, the request id says the rest."""
    return ApiProblem(500, "An unexpected error occurred; it has been logged.", code="internal")


def problem_from_exception(exc: BaseException) -> ApiProblem:
    """Map any exception to its problem details (the single error mapping of the service).

    ============================  ======  =================================================
    exception                     status  notes
    ============================  ======  =================================================
    ApiProblem                    own     raised by the routers (404 job, 409, 413 ...)
    typed error (core, io, jobs)  class   ``status``/``title``/``code`` class attributes,
                                          ``field``, ``message``, extras of ``to_dict()``
    InvalidParams                 422     SmoothingParams; ``errors`` with ``params.<name>``
    InvalidInlineGeometry         422     JSON body ``geometry`` against the schema
    RequestValidationError        422     FastAPI query/path validation
    HTTPException                 own     404 unknown route, 405, 413 ...
    anything else                 500     logged; no internals in the body
    ============================  ======  =================================================
    """
    if isinstance(exc, ApiProblem):
        return exc
    typed = typed_problem(exc)
    if typed is not None:
        return typed
    if isinstance(exc, InvalidInlineGeometry):
        error = {"field": "geometry", "message": exc.message, "type": exc.code}
        return ApiProblem(
            422,
            exc.message,
            code="invalid-geometry",
            title="Invalid geometry",
            field="geometry",
            errors=[error],
        )
    if isinstance(exc, InvalidParams):
        errors = field_errors(exc.error, "params")
        return _validation(errors, "invalid-parameters", "Invalid parameters", "params")
    if isinstance(exc, RequestValidationError):
        return _validation(field_errors(exc, ""), "invalid-request", "Invalid request", None)
    if isinstance(exc, StarletteHTTPException):
        status = exc.status_code
        detail = exc.detail if isinstance(exc.detail, str) else ApiProblem(status, "").title
        return ApiProblem(
            status,
            detail,
            code=_PROTOCOL_CODES.get(status),
            field="body" if status == 400 else None,
            headers=exc.headers,
            max_upload_bytes=getattr(exc, "limit", None),
        )
    return internal_problem()


def problem_response(problem: ApiProblem, instance: str | None = None) -> JSONResponse:
    """Render a problem as an ``application/problem+json`` response."""
    return FiniteJSONResponse(
        problem.body(instance),
        status_code=problem.status,
        media_type=PROBLEM_MEDIA_TYPE,
        headers=problem.headers or None,
    )


_METHODS = ("GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS")


def allowed_methods(request: Request) -> list[str]:
    """Every method some route serves at the request's path (for ``Allow`` of a 405)."""
    routes = request.app.router.routes
    return [
        method
        for method in _METHODS
        if any(r.matches({**request.scope, "method": method})[0] is Match.FULL for r in routes)
    ]


async def _handle(request: Request, exc: Exception) -> JSONResponse:
    problem = problem_from_exception(exc)
    if problem.status == 405:
        problem.headers["Allow"] = ", ".join(allowed_methods(request))
    return problem_response(problem, instance=request.url.path)


def install_problem_handlers(app: FastAPI) -> None:
    """Answer every expected error of ``app`` with problem details."""
    for exc_type in (
        ApiProblem,
        StarletteHTTPException,
        RequestValidationError,
        InvalidParams,
        InvalidInlineGeometry,
    ):
        app.add_exception_handler(exc_type, _handle)  # type: ignore[arg-type]
