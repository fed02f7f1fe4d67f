"""geosmooth JSON: points with optional connectivity, weights, fixed points and attributes.

The schema (also :data:`~service.io.formats.json.schema.GEOMETRY_JSON_SCHEMA`, which the API
reuses)::

    {
      "points":     [[x, y, ...], ...],            n rows of s >= 1 numbers (required)
      "faces":      [[i, j, k], ...],              0-based; polygons are fan-triangulated
      "edges":      [[i, j], ...],                 standalone edges
      "polylines":  [{"indices": [i, j, ...], "closed": false}, ...],
      "weights":    [w_0, ..., w_{n-1}],           positive per-point weights
      "fixed":      [i, ...],                      points kept exactly in place
      "comments":   ["...", ...],                  free text, carried to written files
      "attributes": {"red": [...], "uv": [[u, v], ...]},   per-point values, written back
      "attribute_types": {"red": "uint8"},         dtype of an attribute (default float64/int64)
      "normals":    [[nx, ny, nz], ...],           recomputed on output (or dropped)
      "precision":  "float32"                      how the points were stored
    }

Indices are 0-based. A polyline whose last index repeats its first is closed (stored once).
Faces and edges that repeat a vertex are dropped and noted; indices outside the point list are a
:class:`~service.io.errors.FormatError`; unknown keys are an error too (typos such as ``face``
must not pass silently); booleans are not numbers. A GeoJSON object is read as GeoJSON. The
HTTP API accepts the same object inline in a request body (:func:`geometry_from_json_obj`).

Written files use the same schema; points are written in shortest round-trip form (or the
input's digits / float32 when ``precision`` says so), so they read back bit-identical. An
infinite weight (a fixed point) is written as weight 1 plus an entry in ``fixed``, which means
the same and keeps the file strict JSON.
"""

from __future__ import annotations

import json
from typing import Any, BinaryIO

import numpy as np
from numpy.typing import NDArray

from service.io._shared.assemble import assemble
from service.io._shared.elements import as_indices, check_indices
from service.io._shared.numfmt import format_column
from service.io.document import GeometryDocument, Precision
from service.io.errors import FormatError
from service.io.formats.json.schema import ATTRIBUTE_TYPES, GEOMETRY_JSON_SCHEMA
from service.io.source import Source

__all__ = [
    "GEOMETRY_JSON_SCHEMA",
    "document_to_json_obj",
    "geometry_from_json_obj",
    "read_json",
    "write_json",
]

_KEYS = tuple(GEOMETRY_JSON_SCHEMA["properties"])
GEOJSON_TYPES = {
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


def _has_bool(value: Any, depth: int = 2) -> bool:
    """Whether a (nested) list holds a boolean (numpy would take ``true`` as 1)."""
    if isinstance(value, bool):
        return True
    if depth and isinstance(value, list):
        return any(_has_bool(v, depth - 1) for v in value)
    return False


def _numeric(value: Any, key: str, shape: str) -> NDArray[Any]:
    """``value`` as a numeric array, or a FormatError saying what ``key`` must be."""
    try:
        arr = np.asarray(value)
    except (ValueError, TypeError, OverflowError):
        raise _fail(f"{key!r} must be {shape}") from None
    if arr.size and (arr.dtype.kind not in "iuf" or _has_bool(value)):
        raise _fail(f"{key!r} must be {shape} (numbers only, not booleans or strings)")
    if arr.dtype.kind in "iu" and arr.dtype.itemsize > 8:  # pragma: no cover - numpy object
        raise _fail(f"{key!r} holds integers too large")
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


def _connectivity(obj: dict[str, Any], n: int) -> dict[str, Any]:
    """Faces, edges, polylines, weights and fixed points of a JSON object."""
    out: dict[str, Any] = {"polygons": None, "edges": None, "polylines": []}
    if obj.get("faces"):
        out["polygons"] = _faces(obj["faces"])
        check_indices(out["polygons"][0], n, what="face", fmt="json", counts=out["polygons"][1])
    if obj.get("edges"):
        edges = _numeric(obj["edges"], "edges", "a list of [i, j] index pairs")
        if edges.ndim != 2 or edges.shape[1] != 2:
            raise _fail("'edges' must be a list of [i, j] index pairs")
        edges = _index_list(edges, "edges").reshape(-1, 2)
        check_indices(edges.reshape(-1), n, what="edge", fmt="json", counts=np.full(len(edges), 2))
        out["edges"] = edges
    for k, item in enumerate(obj.get("polylines") or []):
        if not isinstance(item, dict) or "indices" not in item or set(item) - {"indices", "closed"}:
            raise _fail(f"polyline {k} must be an object {{'indices': [...], 'closed': bool}}")
        closed = item.get("closed", False)
        if not isinstance(closed, bool):
            raise _fail(f"polyline {k}: 'closed' must be true or false")
        idx = _index_list(item["indices"], f"polylines[{k}].indices")
        check_indices(idx, n, what="polyline", fmt="json", counts=np.array([idx.size]), start=k)
        out["polylines"].append((idx, closed))
    if obj.get("weights") is not None:
        weights = _numeric(obj["weights"], "weights", "a list of n positive numbers")
        out["weights"] = weights.astype(np.float64)
    if obj.get("fixed"):
        out["fixed"] = _index_list(obj["fixed"], "fixed")
        check_indices(out["fixed"], n, what="fixed point", fmt="json")
    return out


def _attributes(obj: dict[str, Any], n: int) -> dict[str, NDArray[Any]]:
    attrs = obj.get("attributes") or {}
    types = obj.get("attribute_types") or {}
    if not isinstance(attrs, dict) or not isinstance(types, dict):
        raise _fail("'attributes' and 'attribute_types' must be objects")
    out: dict[str, NDArray[Any]] = {}
    for name, values in attrs.items():
        arr = _numeric(values, f"attributes.{name}", "a list of n numbers or n lists of numbers")
        if arr.ndim not in (1, 2) or arr.shape[0] != n:
            raise _fail(f"'attributes.{name}' must hold one value (or list) per point ({n})")
        dtype = types.get(name)
        if dtype is not None:
            if dtype not in ATTRIBUTE_TYPES:
                raise _fail(f"'attribute_types.{name}' must be one of {', '.join(ATTRIBUTE_TYPES)}")
            with np.errstate(over="ignore", invalid="ignore"):
                cast = arr.astype(dtype)
            if not np.array_equal(cast.astype(np.float64), arr.astype(np.float64)):
                raise _fail(f"'attributes.{name}' does not fit its type {dtype}")
            arr = cast
        out[str(name)] = arr
    unknown = sorted(set(types) - set(attrs))
    if unknown:
        raise _fail(f"'attribute_types' names {unknown[0]!r}, which is not an attribute")
    return out


def _normals(obj: dict[str, Any], n: int) -> NDArray[np.float64] | None:
    if obj.get("normals") is None:
        return None
    arr = _numeric(obj["normals"], "normals", "an n x 3 array of numbers")
    if arr.shape != (n, 3):
        raise _fail(f"'normals' must be {n} rows of 3 numbers, got shape {arr.shape}")
    return arr.astype(np.float64)


def geometry_from_json_obj(obj: Any, *, weld: bool = False, fmt: str = "json") -> GeometryDocument:
    """Build a document from a parsed geosmooth JSON object (see the module docstring).

    Parameters
    ----------
    obj : dict
        The decoded JSON object (e.g. part of an HTTP request body). GeoJSON objects are read
        as GeoJSON (see :mod:`service.io.formats.geojson`).
    weld : bool
        Merge exactly coincident points.
    fmt : str
        Recorded as the document's ``source_format``.

    Raises
    ------
    FormatError
        The object does not follow the schema, or an index is out of range.
    GeometryError
        From :class:`~service.core.geometry.Geometry` validation (non-finite coordinates,
        non-positive weights, ...).
    """
    if not isinstance(obj, dict):
        raise _fail(f"top level must be an object with a 'points' key, got {type(obj).__name__}")
    if "points" not in obj:
        if obj.get("type") in GEOJSON_TYPES:
            from service.io.formats.geojson import geojson_document

            return geojson_document(obj, weld=weld)
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
    comments = obj.get("comments") or []
    if not isinstance(comments, list) or not all(isinstance(c, str) for c in comments):
        raise _fail("'comments' must be a list of strings")
    stored = obj.get("precision", "float64")
    if stored not in ("float32", "float64"):
        raise _fail("'precision' must be 'float32' or 'float64'")
    parts = _connectivity(obj, n)
    doc = assemble(points, fmt=fmt, comments=comments, weld=weld, **parts)
    return doc.with_extras(
        attributes=_attributes(obj, n), normals=_normals(obj, n), precision=Precision(stored)
    )


def read_json(source: Source, *, weld: bool = False) -> GeometryDocument:
    """Read a geosmooth JSON file.

    Raises
    ------
    FormatError
        Invalid JSON (with line and column) or an object that does not follow the schema.
    """
    data = source.data()
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
    except ValueError as exc:  # e.g. an integer of more than 4300 digits
        raise FormatError(f"invalid JSON: {exc}", fmt="json") from None
    return geometry_from_json_obj(obj, weld=weld)


def _rows_json(values: NDArray[Any], specs: tuple[str, ...]) -> str:
    cols = [format_column(values[:, j], specs[j]) for j in range(values.shape[1])]
    return "[" + ",".join("[" + ",".join(r) + "]" for r in zip(*cols, strict=True)) + "]"


def document_to_json_obj(
    doc: GeometryDocument, points: NDArray[np.float64] | None = None
) -> dict[str, Any]:
    """The document as a geosmooth JSON object (original vertex count and order if welded)."""
    from service.io._shared.plain import plain_document

    return json.loads(_json_text(plain_document(doc, points)))


def _json_text(plain: Any) -> str:
    out: dict[str, Any] = {}
    if plain.faces is not None and len(plain.faces):
        out["faces"] = plain.faces.tolist()
    if plain.standalone_edges is not None and len(plain.standalone_edges):
        out["edges"] = plain.standalone_edges.tolist()
    if plain.polylines:
        out["polylines"] = [
            {"indices": p.indices.tolist(), "closed": p.closed} for p in plain.polylines
        ]
    weights, fixed = plain.weights, plain.fixed
    if weights is not None:
        inf = ~np.isfinite(weights)
        if inf.any():
            extra = np.flatnonzero(inf)
            fixed = extra if fixed is None else np.union1d(fixed, extra)
            weights = np.where(inf, 1.0, weights)
        out["weights"] = weights.tolist()
    if fixed is not None and len(fixed):
        out["fixed"] = np.asarray(fixed).tolist()
    if plain.comments:
        out["comments"] = list(plain.comments)
    if plain.attributes:
        out["attributes"] = {k: v.tolist() for k, v in plain.attributes.items()}
        types = {
            k: v.dtype.name
            for k, v in plain.attributes.items()
            if v.dtype.name not in ("float64", "int64") and v.dtype.name in ATTRIBUTE_TYPES
        }
        if types:
            out["attribute_types"] = types
    if plain.normals is not None:
        out["normals"] = np.asarray(plain.normals, dtype=np.float64).tolist()
    if plain.coordinate_dtype() == np.float32:
        out["precision"] = "float32"
    rest = json.dumps(out, allow_nan=False, separators=(",", ":"))
    points = _rows_json(plain.points, plain.coordinate_specs())
    return '{"points":' + points + ("," + rest[1:] if len(rest) > 2 else "}")


def write_json(plain: Any, out: BinaryIO) -> None:
    """Write a plain document as geosmooth JSON (UTF-8)."""
    try:
        out.write(_json_text(plain).encode("utf-8"))
    except ValueError as exc:  # a non-finite attribute value
        raise FormatError(f"JSON cannot hold {exc}", fmt="json") from None
