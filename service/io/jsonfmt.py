"""geosmooth JSON: points with optional connectivity, weights and fixed points.

The schema (also :data:`GEOMETRY_JSON_SCHEMA`, a JSON Schema the API reuses)::

    {
      "points":    [[x, y, ...], ...],            n rows of s >= 1 numbers (required)
      "faces":     [[i, j, k], ...],              0-based; polygons are fan-triangulated
      "edges":     [[i, j], ...],                 standalone edges
      "polylines": [{"indices": [i, j, ...], "closed": false}, ...],
      "weights":   [w_0, ..., w_{n-1}],           positive per-point weights
      "fixed":     [i, ...],                      points kept exactly in place
      "comments":  ["...", ...]                   free text, carried to written files
    }

Indices are 0-based. A polyline whose last index repeats its first is closed (stored once).
Faces and edges that repeat a vertex are dropped and noted; indices outside the point list are a
:class:`~service.io.errors.FormatError`; unknown keys are an error too (typos such as ``face``
must not pass silently). The HTTP API accepts the same object inline in a request body
(:func:`geometry_from_json_obj`).

Written files use the same schema; floats are written by Python's ``json`` (``repr``: shortest
round-trip form), so points read back bit-identical. An infinite weight (a fixed point) is
written as weight 1 plus an entry in ``fixed``, which means the same and keeps the file strict
JSON.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np
from numpy.typing import NDArray

from service.io.assemble import assemble
from service.io.document import GeometryDocument
from service.io.elements import as_indices, check_indices
from service.io.errors import FormatError, UnsupportedFormat

__all__ = [
    "GEOMETRY_JSON_SCHEMA",
    "document_to_json_obj",
    "geometry_from_json_obj",
    "read_json",
    "write_json",
]

_INDEX = {"type": "integer", "minimum": 0}

GEOMETRY_JSON_SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "geosmooth geometry",
    "description": "Points (n x s, any s >= 1) with optional 0-based connectivity.",
    "type": "object",
    "required": ["points"],
    "additionalProperties": False,
    "properties": {
        "points": {
            "description": "n points, each a list of s >= 1 coordinates (the same s for all).",
            "type": "array",
            "minItems": 1,
            "items": {"type": "array", "minItems": 1, "items": {"type": "number"}},
        },
        "faces": {
            "description": "Faces as 0-based vertex indices; polygons are fan-triangulated.",
            "type": "array",
            "items": {"type": "array", "minItems": 3, "items": _INDEX},
        },
        "edges": {
            "description": "Standalone edges (0-based vertex index pairs).",
            "type": "array",
            "items": {"type": "array", "minItems": 2, "maxItems": 2, "items": _INDEX},
        },
        "polylines": {
            "description": "Open or closed polylines through 0-based vertex indices.",
            "type": "array",
            "items": {
                "type": "object",
                "required": ["indices"],
                "additionalProperties": False,
                "properties": {
                    "indices": {"type": "array", "minItems": 2, "items": _INDEX},
                    "closed": {"type": "boolean", "default": False},
                },
            },
        },
        "weights": {
            "description": "One positive weight per point (omega_i of the report).",
            "type": "array",
            "items": {"type": "number", "exclusiveMinimum": 0},
        },
        "fixed": {
            "description": "0-based indices of points kept exactly in place.",
            "type": "array",
            "items": _INDEX,
        },
        "comments": {
            "description": "Free text carried to written files.",
            "type": "array",
            "items": {"type": "string"},
        },
    },
}

_KEYS = tuple(GEOMETRY_JSON_SCHEMA["properties"])
_GEOJSON_TYPES = {
    "FeatureCollection",
    "Feature",
    "Point",
    "MultiPoint",
    "LineString",
    "MultiLineString",
    "Polygon",
    "MultiPolygon",
    "GeometryCollection",
}


def _fail(message: str) -> FormatError:
    return FormatError(f"JSON {message}", fmt="json")


def _numeric(value: Any, key: str, shape: str) -> NDArray[Any]:
    """``value`` as a numeric array, or a FormatError saying what ``key`` must be."""
    try:
        arr = np.asarray(value)
    except (ValueError, TypeError):
        raise _fail(f"{key!r} must be {shape}") from None
    if arr.size and arr.dtype.kind not in "iuf":
        raise _fail(f"{key!r} must be {shape}")
    return arr


def _index_list(value: Any, key: str) -> NDArray[np.int64]:
    arr = _numeric(value, key, "a list of integer indices").reshape(-1)
    return as_indices(arr, what=f"JSON {key!r}", fmt="json")


def _faces(value: Any) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    shape = "a list of faces, each a list of 3 or more vertex indices"
    try:
        arr = np.asarray(value)
    except (ValueError, TypeError):
        arr = None
    if arr is not None and arr.ndim == 2 and arr.dtype.kind in "iuf":
        flat = _index_list(arr, "faces")
        return flat, np.full(arr.shape[0], arr.shape[1], dtype=np.int64)
    if not isinstance(value, list) or not all(isinstance(f, list) for f in value):
        raise _fail(f"'faces' must be {shape}")
    counts = np.fromiter((len(f) for f in value), dtype=np.int64, count=len(value))
    flat = _index_list([i for f in value for i in f], "faces")
    return flat, counts


def geometry_from_json_obj(obj: Any, *, weld: bool = False, fmt: str = "json") -> GeometryDocument:
    """Build a document from a parsed geosmooth JSON object (see the module docstring).

    Parameters
    ----------
    obj : dict
        The decoded JSON object (e.g. part of an HTTP request body).
    weld : bool
        Merge exactly coincident points.
    fmt : str
        Recorded as the document's ``source_format``.

    Raises
    ------
    FormatError
        The object does not follow the schema, or an index is out of range.
    UnsupportedFormat
        The object is GeoJSON.
    GeometryError
        From :class:`~service.core.geometry.Geometry` validation (non-finite coordinates,
        non-positive weights, ...).
    """
    if not isinstance(obj, dict):
        raise _fail(f"top level must be an object with a 'points' key, got {type(obj).__name__}")
    if "points" not in obj:
        if obj.get("type") in _GEOJSON_TYPES:
            raise UnsupportedFormat(
                "GeoJSON is not supported: convert each LineString to a polyline, as geosmooth"
                " JSON {'points', 'polylines'} or OBJ 'v' + 'l' lines",
                fmt="geojson",
            )
        raise _fail("object has no 'points' key")
    unknown = sorted(set(obj) - set(_KEYS))
    if unknown:
        raise _fail(f"unknown key {unknown[0]!r} (expected one of {', '.join(_KEYS)})")
    points = _numeric(obj["points"], "points", "an n x s array of numbers")
    if points.ndim != 2 or points.shape[0] < 1 or points.shape[1] < 1:
        raise _fail(
            "'points' must be a non-empty list of points, each a non-empty list of numbers"
            f" of the same length (got shape {points.shape})"
        )
    n = points.shape[0]
    polygons = None
    if obj.get("faces"):
        polygons = _faces(obj["faces"])
        check_indices(polygons[0], n, what="face", fmt="json", counts=polygons[1])
    edges = None
    if obj.get("edges"):
        edges = _numeric(obj["edges"], "edges", "a list of [i, j] index pairs")
        if edges.ndim != 2 or edges.shape[1] != 2:
            raise _fail("'edges' must be a list of [i, j] index pairs")
        edges = _index_list(edges, "edges").reshape(-1, 2)
        check_indices(edges.reshape(-1), n, what="edge", fmt="json", counts=np.full(len(edges), 2))
    polylines: list[tuple[NDArray[np.int64], bool]] = []
    for k, item in enumerate(obj.get("polylines") or []):
        if not isinstance(item, dict) or "indices" not in item or set(item) - {"indices", "closed"}:
            raise _fail(f"polyline {k} must be an object {{'indices': [...], 'closed': bool}}")
        closed = item.get("closed", False)
        if not isinstance(closed, bool):
            raise _fail(f"polyline {k}: 'closed' must be true or false")
        idx = _index_list(item["indices"], f"polylines[{k}].indices")
        check_indices(idx, n, what="polyline", fmt="json", counts=np.array([idx.size]), start=k)
        polylines.append((idx, closed))
    weights = None
    if obj.get("weights") is not None:
        weights = _numeric(obj["weights"], "weights", "a list of n positive numbers")
        weights = weights.astype(np.float64)
    fixed = None
    if obj.get("fixed"):
        fixed = _index_list(obj["fixed"], "fixed")
        check_indices(fixed, n, what="fixed point", fmt="json")
    comments = obj.get("comments") or []
    if not isinstance(comments, list) or not all(isinstance(c, str) for c in comments):
        raise _fail("'comments' must be a list of strings")
    return assemble(
        points,
        fmt=fmt,
        polygons=polygons,
        edges=edges,
        polylines=polylines,
        weights=weights,
        fixed=fixed,
        comments=comments,
        weld=weld,
    )


def read_json(data: bytes, *, weld: bool = False) -> GeometryDocument:
    """Read a geosmooth JSON file from bytes.

    Raises
    ------
    FormatError
        Invalid JSON (with line and column) or an object that does not follow the schema.
    """
    if not data.strip():
        raise FormatError("the file is empty", fmt="json")
    try:
        obj = json.loads(data)
    except json.JSONDecodeError as exc:
        raise FormatError(
            f"line {exc.lineno} column {exc.colno}: invalid JSON: {exc.msg}",
            fmt="json",
            line=exc.lineno,
        ) from None
    except UnicodeDecodeError:
        raise FormatError("the file is not UTF-8 text", fmt="json") from None
    except RecursionError:
        raise FormatError("the JSON is nested too deeply", fmt="json") from None
    return geometry_from_json_obj(obj, weld=weld)


def document_to_json_obj(
    doc: GeometryDocument, points: NDArray[np.float64] | None = None
) -> dict[str, Any]:
    """The document as a geosmooth JSON object (original vertex count and order if welded).

    Parameters
    ----------
    doc : GeometryDocument
        What to write.
    points : ndarray, optional
        Replacement (e.g. smoothed) points, shaped like ``doc.geometry.points``.
    """
    out: dict[str, Any] = {"points": doc.output_points(points).tolist()}
    faces = doc.output_faces()
    if faces is not None and len(faces):
        out["faces"] = faces.tolist()
    edges = doc.output_standalone_edges()
    if edges is not None and len(edges):
        out["edges"] = edges.tolist()
    polylines = doc.output_polylines()
    if polylines:
        out["polylines"] = [{"indices": p.indices.tolist(), "closed": p.closed} for p in polylines]
    weights = doc.output_weights()
    fixed = doc.output_fixed()
    if weights is not None:
        inf = ~np.isfinite(weights)
        if inf.any():
            extra = np.flatnonzero(inf)
            fixed = extra if fixed is None else np.union1d(fixed, extra)
            weights = np.where(inf, 1.0, weights)
        out["weights"] = weights.tolist()
    if fixed is not None and len(fixed):
        out["fixed"] = np.asarray(fixed).tolist()
    if doc.comments:
        out["comments"] = list(doc.comments)
    return out


def write_json(doc: GeometryDocument, points: NDArray[np.float64] | None = None) -> bytes:
    """Write a document as geosmooth JSON (UTF-8 bytes)."""
    obj = document_to_json_obj(doc, points)
    return json.dumps(obj, allow_nan=False, separators=(",", ":")).encode("utf-8")
