"""What runs in a worker process for a request: parse, check, (smooth), answer a small dict.

The server process never parses geometry or JSON bodies itself: :mod:`service.api.intake.isolation`
starts one process per request with one of the functions below, bounded in time and address
space, killable when the client goes away. Each returns a small JSON-ready dict; every error is
answered as problem details (:class:`~service.api.errors.ApiProblem`), with the spool paths
replaced by the uploaded file name (no server path ever reaches a client).

Checks, cheapest first: parameters (422) and the key's bounds on them (``k``,
``max_iterations``: 422), the format (415), the file (400 malformed, 422 invalid geometry), the
key's size bounds (points, faces: 413; ``spectrum``: 422). What a job or a synchronous answer
checks and runs next is the use cases' (:mod:`service.api.intake.smoothing`: the submit check of
:mod:`service.workflows.admission`, the read -> smooth -> write of
:mod:`service.workflows.smooth_file`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from pydantic import ValidationError

from service.api.errors import ApiProblem, finite
from service.api.http.bounds import Limits
from service.core.params import SmoothingParams
from service.io import FORMATS, GeometryDocument, geometry_from_json_obj, read_geometry
from service.io.dispatch import detect_format, sniff_format
from service.io.errors import FormatError, UnsupportedFormat

__all__ = ["IngestRequest", "ParsedRequest", "describe_input", "parse_request"]

_TRUE, _FALSE = frozenset({"true", "1", "yes", "on"}), frozenset({"false", "0", "no", "off", ""})
_JSON_MEMBERS = frozenset({"geometry", "params", "weld", "webhook_url"})


@dataclass(frozen=True)
class IngestRequest:
    """A spooled request (picklable: sent to the worker process).

    Attributes
    ----------
    kind : {"multipart", "json"}
        How it came; ``path`` is the file part, or the whole JSON body.
    path : str
        Spool file.
    filename, part_type : str or None
        Name and ``Content-Type`` of the file part.
    fields : dict
        Text of the small multipart parts.
    limits : Limits
        The key's bounds.
    work_dir : str
        Where output files go (the spool directory).
    params_required : bool
        ``False``: missing ``params`` means the defaults (``POST /v1/info``).
    out_format : str or None
        ``POST /v1/smooth``: the answer's format (default: the input's).
    exact_tau_max_points : int
        Largest point cloud whose ``tau`` is checked exactly at submit (see
        :mod:`service.core.tau_range`).
    options : dict
        Endpoint-specific options of the worker function (e.g. ``preview`` of ``/v1/info``).
    """

    kind: Literal["multipart", "json"]
    path: str
    filename: str | None
    part_type: str | None
    fields: dict[str, str]
    limits: Limits
    work_dir: str
    params_required: bool = True
    out_format: str | None = None
    exact_tau_max_points: int = 50_000
    options: dict[str, Any] = field(default_factory=dict)


@dataclass
class ParsedRequest:
    """A parsed, checked request: the document, parameters and the small parts."""

    document: GeometryDocument
    params: SmoothingParams
    fmt: str
    weld: bool
    webhook_url: str | None
    input_path: str
    extra: dict[str, Any] = field(default_factory=dict)


def _invalid(
    field_name: str,
    detail: str,
    code: str = "invalid-request",
    title: str = "Invalid request",
    status: int = 422,
) -> ApiProblem:
    error = {"field": field_name, "message": detail, "type": code}
    return ApiProblem(status, detail, code=code, title=title, field=field_name, errors=[error])


def _params(raw: Any, required: bool) -> SmoothingParams:
    if raw is None:
        if required:
            raise _invalid(
                "params", "a 'params' part or member (JSON object) is required", "missing-field"
            )
        return SmoothingParams.model_construct()
    if isinstance(raw, str):
        try:
            raw = json.loads(raw)
        except (ValueError, RecursionError) as exc:
            why = exc.msg if isinstance(exc, json.JSONDecodeError) else "unreadable number/nesting"
            raise _invalid(
                "params",
                f"params is not valid JSON: {why}",
                "invalid-parameters",
                "Invalid parameters",
            ) from None
    if not isinstance(raw, dict):
        raise _invalid(
            "params",
            'params must be a JSON object, e.g. {"rms": 0.001}',
            "invalid-parameters",
            "Invalid parameters",
        )
    try:
        return SmoothingParams.model_validate(raw)
    except ValidationError as exc:
        errors = [
            {
                "field": ".".join(["params", *map(str, e["loc"])]).rstrip("."),
                "message": str(e["msg"]).removeprefix("Value error, "),
                "type": e["type"],
            }
            for e in exc.errors(include_url=False, include_input=False)
        ]
        detail = "; ".join(f"{e['field']}: {e['message']}" for e in errors)
        raise ApiProblem(
            422,
            detail,
            code="invalid-parameters",
            title="Invalid parameters",
            field=errors[0]["field"],
            errors=errors,
        ) from None


def _check_param_bounds(params: SmoothingParams, limits: Limits, kind: str | None = None) -> None:
    """The key's bounds on ``max_iterations`` and, for point clouds (``kind``), on ``k``."""
    bounds = [("max_iterations", limits.max_iterations)]
    if kind == "cloud":
        bounds.append(("k", limits.max_k))
    for name, bound in bounds:
        value = getattr(params, name, None)
        if value is not None and value > bound:
            raise _invalid(
                f"params.{name}",
                f"params.{name}={value} exceeds this key's bound of {bound}",
                "bound-exceeded",
                "Invalid parameters",
            )


def _flag(raw: str | None) -> bool | None:
    """``weld`` as given (``None``: not given, the format's default applies)."""
    text = (raw or "").strip().lower()
    if not text:
        return None
    if text in _TRUE:
        return True
    if text in _FALSE:
        return False
    raise _invalid("weld", "weld must be true or false")


_GENERIC_TYPES = frozenset({"application/octet-stream", "text/plain", "binary/octet-stream"})


def _media_format(part_type: str | None) -> str | None:
    """The format a specific part ``Content-Type`` names (generic types name none)."""
    if not part_type or part_type.lower() in _GENERIC_TYPES:
        return None
    names = [n for n, f in FORMATS.items() if f.media_type.split(";")[0] == part_type]
    return names[0] if len(names) == 1 else None


def _format(req: IngestRequest) -> str:
    """Explicit ``input_format`` part (``format``: its deprecated name), else the file name, the
    part's content type, the content."""
    explicit = req.fields.get("input_format", "").strip()
    former = req.fields.get("format", "").strip()
    if explicit and former and explicit.lower() != former.lower():
        raise _invalid(
            "input_format", f"input_format={explicit} and format={former} (its deprecated name) "
            "disagree",
        )  # fmt: skip
    explicit = explicit or former
    if explicit:
        fmt = explicit.lower().lstrip(".")
        if fmt not in FORMATS:
            raise UnsupportedFormat(
                f"unsupported format {explicit!r}; use one of {', '.join(FORMATS)}", fmt=fmt
            )
        return fmt
    if req.filename and Path(req.filename).suffix:
        return detect_format(req.filename)  # UnsupportedFormat -> 415
    by_type = _media_format(req.part_type)
    if by_type is not None:
        return by_type
    with open(req.path, "rb") as fh:
        head = fh.read(4096)
    if not head.strip():
        raise FormatError("the uploaded file is empty")
    sniffed = sniff_format(head)
    if sniffed is None:
        raise UnsupportedFormat(
            "cannot tell the input format: give the file name an extension "
            f"or send a format part ({', '.join(FORMATS)})"
        )
    return sniffed


def _from_multipart(req: IngestRequest) -> ParsedRequest:
    params = _params(req.fields.get("params"), req.params_required)
    _check_param_bounds(params, req.limits)
    fmt = _format(req)
    given = _flag(req.fields.get("weld"))
    weld = FORMATS[fmt].weld_default if given is None else given  # STL, GLB: welded
    if Path(req.path).stat().st_size == 0:
        raise FormatError("the uploaded file is empty", fmt=fmt)
    try:
        document = read_geometry(Path(req.path), fmt, filename=req.filename, weld=weld)
    except RecursionError:
        raise FormatError("the file is nested too deeply", fmt=fmt) from None
    url = req.fields.get("webhook_url", "").strip() or None
    return ParsedRequest(document, params, fmt, weld, url, req.path)


def _from_json(req: IngestRequest) -> ParsedRequest:
    try:
        obj = json.loads(Path(req.path).read_bytes())
    except (ValueError, RecursionError) as exc:
        why = exc.msg if isinstance(exc, json.JSONDecodeError) else "unreadable number/nesting"
        raise _invalid(
            "body", f"request body is not valid JSON: {why}", "invalid-json", status=400
        ) from None
    if not isinstance(obj, dict):
        raise _invalid("body", "the JSON body must be an object {geometry, params}")
    unknown = sorted(set(obj) - _JSON_MEMBERS)
    if unknown:
        raise _invalid(
            unknown[0],
            f"unknown member(s): {', '.join(unknown)}; expected "
            "geometry, params, weld, webhook_url",
        )
    if "params" in obj and not isinstance(obj["params"], dict):
        raise _invalid(
            "params", "params must be a JSON object", "invalid-parameters", "Invalid parameters"
        )
    params = _params(obj.get("params"), req.params_required)
    _check_param_bounds(params, req.limits)
    weld, url = obj.get("weld", False), obj.get("webhook_url")
    if not isinstance(weld, bool):
        raise _invalid("weld", "weld must be true or false")
    if url is not None and not isinstance(url, str):
        raise _invalid("webhook_url", "webhook_url must be a string")
    geometry = obj.get("geometry")
    if not isinstance(geometry, dict):
        raise _invalid(
            "geometry", "a 'geometry' member (object with points) is required", "missing-field"
        )
    try:
        document = geometry_from_json_obj(geometry, weld=weld)
    except UnsupportedFormat:
        raise
    except (FormatError, RecursionError) as exc:
        message = exc.message if isinstance(exc, FormatError) else "nested too deeply"
        raise _invalid("geometry", message, "invalid-geometry", "Invalid geometry") from None
    return ParsedRequest(document, params, "json", weld, url, req.path, {"geometry": geometry})


def _check_size(parsed: ParsedRequest, max_points: int, limits: Limits) -> None:
    geometry = parsed.document.geometry
    n = int(geometry.n)
    if n > max_points:
        raise ApiProblem(
            413,
            f"the input has {n} points; this server accepts at most {max_points}",
            code="too-many-points",
            field="geometry.points",
            n_points=n,
            max_points=max_points,
        )
    faces = 0 if geometry.faces is None else len(geometry.faces)
    if faces > limits.max_faces:
        raise ApiProblem(
            413,
            f"the input has {faces} faces; this server accepts at most {limits.max_faces}",
            code="too-many-faces",
            field="geometry.faces",
            n_faces=faces,
            max_faces=limits.max_faces,
        )
    if parsed.params.spectrum and n > limits.max_spectrum_points:
        raise _invalid(
            "params.spectrum",
            f"the spectrum is available for inputs of at most "
            f"{limits.max_spectrum_points} points (this one has {n})",
            "bound-exceeded",
            "Invalid parameters",
        )


def parse_request(req: IngestRequest, max_points: int | None = None) -> ParsedRequest:
    """Parse and check a spooled request (in a worker process; see the module docstring).

    ``max_points`` defaults to the key's ``max_points``. Routers with their own worker function
    (e.g. ``POST /v1/info``) start from this.
    """
    parsed = _from_json(req) if req.kind == "json" else _from_multipart(req)
    _check_size(parsed, req.limits.max_points if max_points is None else max_points, req.limits)
    _check_param_bounds(parsed.params, req.limits, str(parsed.document.geometry.kind))
    return parsed


def _bound_only(geometry: Any, params: SmoothingParams, exact_max_points: int) -> bool:
    """Whether ``POST /v1/jobs`` checks this input against the closed-form bound of phi(0)
    only (a cloud above ``exact_max_points`` without fixed points): ``POST /v1/info`` then
    does the same, so it accepts every input a job accepts within the same memory budget."""
    fixed = geometry.fixed is not None or params.fix_boundary
    return bool(geometry.kind == "cloud" and geometry.n > exact_max_points and not fixed)


def _outline(geometry: Any) -> dict[str, Any]:
    """:func:`~service.core.info.describe`'s answer with the centroid bound as ``phi0``
    (``phi0_exact`` false) and no neighbourhood graph, noise estimate or suggestion: those
    cost as much as the job's first stage, which computes them (the automatic tau)."""
    import numpy as np

    from service.core.info import mean_spacing
    from service.core.tau_range import centroid_bound

    phi0, weight = centroid_bound(geometry)
    pts = geometry.points
    return {
        "n_points": geometry.n,
        "dimension": geometry.dim,
        "kind": geometry.kind,
        "n_faces": 0,
        "n_edges": None,
        "bbox": {"min": pts.min(axis=0).tolist(), "max": pts.max(axis=0).tolist()},
        "mean_spacing": mean_spacing(geometry),
        "phi0": phi0,
        "phi0_exact": False,
        "tau_range": [0.0, phi0],
        "rms_range": [0.0, float(np.sqrt(phi0 / weight)) if weight > 0 else 0.0],
        "sigma_estimate": None,
        "suggested_tau": None,
        "suggested_rms": None,
    }


def describe_input(req: IngestRequest) -> dict[str, Any]:
    """``POST /v1/info``: :func:`service.core.info.describe` of the input, plus what the reader
    saw (``format``, ``filename``, ``n_polylines``, ``notes``, ``weld``) and, with the option
    ``preview``, the display arrays of :mod:`service.api.intake.preview`."""
    from service.core.info import describe

    parsed = parse_request(req)
    geometry = parsed.document.geometry
    if _bound_only(geometry, parsed.params, req.exact_tau_max_points):
        info = _outline(geometry)  # what POST /v1/jobs checks for this input, no more
    else:
        info = describe(geometry, parsed.params)
        info["phi0_exact"] = True
    info.update(
        input_format=parsed.fmt,
        format=parsed.fmt,  # deprecated name of input_format
        filename=req.filename,
        n_polylines=len(parsed.document.polylines),
        notes=list(parsed.document.notes),
        weld=parsed.weld,
    )
    if req.options.get("preview"):
        from service.api.intake.preview import preview_dict

        info["preview"] = preview_dict(parsed.document)
    return finite(info)  # type: ignore[no-any-return]
