"""Reading a smoothing request: a multipart upload or a JSON body, validated before any work.

Order of checks (cheapest first): content type, parameters (422), format (415), then the
geometry is parsed in a worker thread (400 malformed file, 422 invalid geometry) and its size
checked against ``max_points`` (413). Inline JSON geometry that does not follow the schema is a
422 on ``geometry``.

Parsing in the request costs little next to the upload for binary files (100K-vertex binary PLY,
3.8 MB: ~25 ms of an ~85 ms POST) and about 1 s for the same mesh as 9.5 MB of ASCII PLY; it runs
in a worker thread, and in exchange no malformed file is ever queued.

The request body itself is size-limited while it streams in by
:class:`service.api.limits.BodySizeLimitMiddleware`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

from fastapi import Request
from pydantic import ValidationError
from starlette.concurrency import run_in_threadpool
from starlette.datastructures import UploadFile

from service.api.problems import ApiProblem, InvalidInlineGeometry, InvalidParams
from service.core.params import SmoothingParams
from service.io import (
    FORMATS,
    FormatError,
    GeometryDocument,
    UnsupportedFormat,
    detect_format,
    geometry_from_json_obj,
    read_geometry,
)

__all__ = ["SmoothInput", "read_smooth_input"]

_FORM_FIELDS = frozenset({"file", "params", "format", "weld"})
_TRUE, _FALSE = frozenset({"true", "1", "yes", "on"}), frozenset({"false", "0", "no", "off", ""})


@dataclass(frozen=True)
class SmoothInput:
    """A validated smoothing request.

    Attributes
    ----------
    data : bytes
        The input file (for a JSON body: the geometry object serialized as a JSON file).
    fmt : str
        Input format.
    filename : str or None
        Uploaded file name.
    params : SmoothingParams
        Validated parameters.
    document : GeometryDocument
        The parsed input.
    weld : bool
        Exactly coincident vertices were welded on reading (and will be in the job).
    """

    data: bytes
    fmt: str
    filename: str | None
    params: SmoothingParams
    document: GeometryDocument
    weld: bool = False


def _missing(field: str, detail: str) -> ApiProblem:
    return ApiProblem(
        422,
        detail,
        code="missing-field",
        title="Invalid request",
        field=field,
        errors=[{"field": field, "message": detail, "type": "missing"}],
    )


def _params(raw: Any) -> SmoothingParams:
    if isinstance(raw, str):
        try:
            raw = json.loads(raw)
        except (json.JSONDecodeError, RecursionError) as exc:
            why = (
                f"{exc.msg} (char {exc.pos})"
                if isinstance(exc, json.JSONDecodeError)
                else "nested too deeply"
            )
            raise ApiProblem(
                422,
                f"params is not valid JSON: {why}",
                code="invalid-parameters",
                title="Invalid parameters",
                field="params",
                errors=[{"field": "params", "message": "not valid JSON", "type": "json_invalid"}],
            ) from None
    if not isinstance(raw, dict):
        raise ApiProblem(
            422,
            'params must be a JSON object, e.g. {"tau": 0.5}',
            code="invalid-parameters",
            title="Invalid parameters",
            field="params",
            errors=[{"field": "params", "message": "must be an object", "type": "dict_type"}],
        )
    try:
        return SmoothingParams.model_validate(raw)
    except ValidationError as exc:
        raise InvalidParams(exc) from None  # -> 422 with params.<name>


def _format(explicit: str | None, filename: str | None) -> str:
    if explicit:
        fmt = explicit.strip().lower().lstrip(".")
        if fmt not in FORMATS:
            raise ApiProblem(
                415,
                f"unsupported format {explicit!r}; use one of {', '.join(FORMATS)}",
                code="unsupported-format",
                title="Unsupported format",
                field="format",
            )
        return fmt
    if not filename:
        raise ApiProblem(
            415,
            "cannot tell the input format: upload a file name with an extension"
            f" or give a format field ({', '.join(FORMATS)})",
            code="unsupported-format",
            title="Unsupported format",
            field="format",
        )
    return detect_format(filename)  # UnsupportedFormat -> 415


def _bad_weld() -> ApiProblem:
    return ApiProblem(
        422,
        "weld must be true or false",
        code="invalid-request",
        title="Invalid request",
        field="weld",
    )


def _flag(raw: Any) -> bool:
    """A form field's boolean (``true``/``false``, ``1``/``0``); absent means false."""
    if raw is None:
        return False
    text = str(raw).strip().lower() if isinstance(raw, str) else None
    if text in _TRUE:
        return True
    if text in _FALSE:
        return False
    raise _bad_weld()


async def _from_multipart(
    request: Request,
) -> tuple[bytes, str | None, str | None, Any, bool]:
    form = await request.form(max_files=1, max_fields=len(_FORM_FIELDS), max_part_size=1 << 20)
    try:
        unknown = sorted(set(form.keys()) - _FORM_FIELDS)
        if unknown:
            raise ApiProblem(
                422,
                f"unknown form field(s): {', '.join(unknown)}; expected file, params, format, weld",
                code="invalid-request",
                title="Invalid request",
                field=unknown[0],
            )
        upload = form.get("file")
        if not isinstance(upload, UploadFile):
            raise _missing("file", "a file part named 'file' is required")
        params = form.get("params")  # None: checked by read_smooth_input
        fmt = form.get("format")
        weld = _flag(form.get("weld"))
        data = await upload.read()
        return data, upload.filename, fmt if isinstance(fmt, str) else None, params, weld
    finally:
        await form.close()


async def _from_json(request: Request) -> tuple[bytes, Any, Any, bool]:
    body = await request.body()
    try:
        obj = await run_in_threadpool(json.loads, body)  # large bodies: not on the event loop
    except (ValueError, RecursionError) as exc:  # JSONDecodeError, UnicodeDecodeError
        raise ApiProblem(
            400, f"request body is not valid JSON: {exc}", code="invalid-json", field="body"
        ) from None
    if not isinstance(obj, dict):
        raise ApiProblem(
            422,
            "the JSON body must be an object {geometry, params}",
            code="invalid-request",
            field="body",
        )
    unknown = sorted(set(obj) - {"geometry", "params", "weld"})
    if unknown:
        raise ApiProblem(
            422,
            f"unknown member(s): {', '.join(unknown)}; expected geometry, params and weld",
            code="invalid-request",
            title="Invalid request",
            field=unknown[0],
        )
    if not isinstance(obj.get("geometry"), dict):
        raise _missing("geometry", "a 'geometry' member (object with points) is required")
    weld = obj.get("weld", False)
    if not isinstance(weld, bool):
        raise _bad_weld()
    data = (await run_in_threadpool(_compact, obj["geometry"])).encode()
    return data, obj.get("params"), obj["geometry"], weld


def _compact(obj: Any) -> str:
    return json.dumps(obj, separators=(",", ":"))


def _read_file(data: bytes, fmt: str, filename: str | None, weld: bool) -> GeometryDocument:
    try:
        return read_geometry(data, fmt, filename=filename, weld=weld)
    except RecursionError:  # e.g. JSON nested thousands deep: malformed, not a server error
        raise FormatError("the file is nested too deeply", fmt=fmt) from None


def _inline_document(geometry: Any, weld: bool) -> GeometryDocument:
    try:
        return geometry_from_json_obj(geometry, weld=weld)
    except UnsupportedFormat:
        raise
    except FormatError as exc:
        raise InvalidInlineGeometry(exc) from None


def _given_params(raw: Any, required: bool) -> SmoothingParams:
    if raw is not None:
        return _params(raw)
    if required:
        raise _missing("params", "a 'params' part or member (JSON object) is required")
    return SmoothingParams.model_construct()  # the defaults, no target (POST /v1/info)


async def read_smooth_input(
    request: Request, max_points: int, *, params_required: bool = True
) -> SmoothInput:
    """Read, validate and parse the smoothing request of ``request``.

    Parameters
    ----------
    request : Request
        ``multipart/form-data`` (``file``, ``params``, optional ``format``) or
        ``application/json`` (``{"geometry": {...}, "params": {...}}``).
    max_points : int
        Largest input accepted (points); larger gives 413.
    params_required : bool
        ``False`` (``POST /v1/info``): without ``params`` the defaults are used, with no target.

    Raises
    ------
    ApiProblem, InvalidParams, InvalidInlineGeometry, FormatError, GeometryError
        Mapped to problem details by :mod:`service.api.problems`.
    """
    ctype = request.headers.get("content-type", "").split(";")[0].strip().lower()
    if ctype == "multipart/form-data":
        data, filename, explicit, raw_params, weld = await _from_multipart(request)
        params = _given_params(raw_params, params_required)
        fmt = _format(explicit, filename)
        if not data:
            raise ApiProblem(400, "the uploaded file is empty", code="format-error", field="file")
        document = await run_in_threadpool(_read_file, data, fmt, filename, weld)
    elif ctype == "application/json" or ctype.endswith("+json"):
        data, raw_params, geometry, weld = await _from_json(request)
        params = _given_params(raw_params, params_required)
        filename, fmt = None, "json"
        document = await run_in_threadpool(_inline_document, geometry, weld)
    else:
        raise ApiProblem(
            415,
            f"unsupported content type {ctype or '(none)'!r}: send multipart/form-data"
            " (file, params[, format]) or application/json ({geometry, params})",
            code="unsupported-media-type",
            title="Unsupported Media Type",
            field="content-type",
        )
    n = document.geometry.n
    if n > max_points:
        raise ApiProblem(
            413,
            f"the input has {n} points; this server accepts at most {max_points}",
            code="too-many-points",
            field="geometry.points",
            n_points=n,
            max_points=max_points,
        )
    return SmoothInput(data, fmt, filename, params, document, weld)
