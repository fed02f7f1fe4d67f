"""GeoJSON lines (RFC 7946), smoothed in metres.

Reading
-------
Every LineString, every line of a MultiLineString and every ring of a (Multi)Polygon, in
Features, FeatureCollections and GeometryCollections, is a polyline; a ring (or line) whose last
position repeats its first is closed. Positions are longitude, latitude[, elevation] in WGS84,
taken to the local east/north/up frame about the data's centre (:mod:`.geodata`), so ``rms=3``
means 3 m; ``geographic=False`` (or a ``crs`` member naming a projected system, or coordinates
outside longitude/latitude ranges) smooths them as planar numbers. Points, properties, ids and
foreign members are kept as they are. Booleans and strings are not coordinates.

Writing
-------
The input object with new positions (the repeated last position of a closed ring follows its
first), rounded to the decimals the input used, written compactly. Other documents become a
FeatureCollection with one LineString per polyline (x = longitude, y = latitude).
"""

from __future__ import annotations

import json
import sys
from collections.abc import Iterator
from dataclasses import dataclass, replace
from typing import Any, BinaryIO

import numpy as np

from service.io._shared.assemble import assemble
from service.io._shared.geodata import GeoFrame, near
from service.io._shared.plain import PlainDocument
from service.io.document import GeometryDocument, Precision
from service.io.errors import FormatError
from service.io.source import Source

__all__ = ["GeoJsonLayout", "geojson_document", "read_geojson", "write_geojson"]

_GEOGRAPHIC_CRS = ("CRS84", "EPSG::4326", "EPSG:4326", "EPSG::4979", "CRS:84")


@dataclass(frozen=True, eq=False)
class GeoJsonLayout:
    """The input object (re-walked on write), its frame and coordinate decimals."""

    obj: Any
    frame: GeoFrame
    digits: int
    data: bytes | None = None


def _fail(message: str) -> FormatError:
    return FormatError(f"GeoJSON {message}", fmt="geojson")


def _lines(obj: Any) -> Iterator[list[list[Any]]]:
    """The position lists of every line and ring, in document order."""
    if not isinstance(obj, dict):
        return
    kind = obj.get("type")
    if kind == "FeatureCollection":
        for f in obj.get("features") or []:
            yield from _lines(f)
    elif kind == "Feature":
        yield from _lines(obj.get("geometry"))
    elif kind == "GeometryCollection":
        for g in obj.get("geometries") or []:
            yield from _lines(g)
    elif kind in ("LineString", "MultiLineString", "Polygon", "MultiPolygon"):
        coords = obj.get("coordinates")
        depth = {"LineString": 0, "MultiLineString": 1, "Polygon": 1, "MultiPolygon": 2}[kind]
        yield from _walk(coords, depth, kind)


def _walk(coords: Any, depth: int, kind: str) -> Iterator[list[list[Any]]]:
    if not isinstance(coords, list):
        raise _fail(f"{kind} coordinates must be nested lists")
    if depth == 0:
        yield coords
        return
    for part in coords:
        yield from _walk(part, depth - 1, kind)


_FLOAT_MAX = sys.float_info.max


def _check(line: list[Any]) -> int:
    """Dimension of a line's positions (2 or 3); FormatError for anything else."""
    dims = set()
    for pos in line:
        if not isinstance(pos, list) or not 2 <= len(pos) <= 3:
            raise _fail("positions must be [longitude, latitude] or [lon, lat, elevation]")
        for v in pos:
            if isinstance(v, bool) or not isinstance(v, int | float):
                raise _fail(f"a coordinate must be a number, got {json.dumps(v)[:20]}")
            if isinstance(v, int) and not -_FLOAT_MAX <= v <= _FLOAT_MAX:  # float(v) overflows
                raise _fail(f"a coordinate is out of range, got {str(v)[:20]}...")
        dims.add(len(pos))
    return min(dims) if dims else 2


def _geographic(obj: dict[str, Any], lon: Any, lat: Any, wanted: bool | None) -> bool:
    if wanted is not None:
        return wanted
    crs = json.dumps(obj.get("crs")) if "crs" in obj else ""
    if crs and not any(name in crs for name in _GEOGRAPHIC_CRS):
        return False
    return bool(np.all(np.abs(lon) <= 180) and np.all(np.abs(lat) <= 90))


def geojson_document(
    obj: Any, *, weld: bool = False, geographic: bool | None = None, digits: int = 9
) -> GeometryDocument:
    """A document from a parsed GeoJSON object (see the module docstring)."""
    lines = [ln for ln in _lines(obj) if ln]
    dims = [_check(ln) for ln in lines]
    lines = [ln for ln in lines if len(ln) >= 2]
    if not lines:
        raise _fail("has no LineString, MultiLineString or Polygon with two or more positions")
    flat = [pos for ln in lines for pos in _open(ln)]
    lon = np.array([p[0] for p in flat], dtype=np.float64)
    lat = np.array([p[1] for p in flat], dtype=np.float64)
    has_ele = min(dims) == 3
    ele = np.array([p[2] if has_ele else 0.0 for p in flat], dtype=np.float64)
    geo = _geographic(obj, lon, lat, geographic)
    frame = GeoFrame.of(lon, lat, has_ele, geo)
    polylines = []
    at = 0
    for ln in lines:
        k = len(_open(ln))
        polylines.append((np.arange(at, at + k), k < len(ln)))
        at += k
    notes = [
        f"{len(lines)} lines, {len(flat)} positions"
        + (" smoothed in metres (local east/north/up frame)" if geo else " (planar)")
    ]
    doc = assemble(
        frame.points(lon, lat, ele), fmt="geojson", polylines=polylines, notes=notes, weld=weld
    )
    return doc.with_extras(layout=GeoJsonLayout(obj, frame, digits), precision=Precision())


def _open(line: list[Any]) -> list[Any]:
    """The positions without a repeated closing one."""
    return line[:-1] if len(line) >= 3 and line[0] == line[-1] else line


def read_geojson(
    source: Source, *, weld: bool = False, geographic: bool | None = None
) -> GeometryDocument:
    """Read a GeoJSON file (see the module docstring)."""
    data = source.data()
    if not data.strip():
        raise FormatError("the file is empty", fmt="geojson")
    most = [0]

    def number(text: str) -> float:
        if "e" not in text.lower() and "." in text:
            most[0] = max(most[0], len(text) - text.index(".") - 1)
        return float(text)

    try:
        obj = json.loads(data, parse_float=number)
    except json.JSONDecodeError as exc:
        raise FormatError(
            f"line {exc.lineno} column {exc.colno}: invalid JSON: {exc.msg}",
            fmt="geojson",
            line=exc.lineno,
        ) from None
    except (UnicodeDecodeError, RecursionError, ValueError) as exc:
        raise FormatError(
            f"invalid JSON: {' '.join(str(exc).split())[:200]}", fmt="geojson"
        ) from None
    doc = geojson_document(obj, weld=weld, geographic=geographic, digits=max(most[0], 1))
    assert isinstance(doc.layout, GeoJsonLayout)
    return doc.with_extras(layout=replace(doc.layout, data=data))


def write_geojson(plain: PlainDocument, out: BinaryIO) -> None:
    """Write a plain document as GeoJSON (see the module docstring)."""
    layout = plain.layout
    if isinstance(layout, GeoJsonLayout) and layout.data is not None and not plain.moved:
        out.write(layout.data)
        return
    if not isinstance(layout, GeoJsonLayout):
        obj = _fresh(plain)
    else:
        obj = json.loads(json.dumps(layout.obj))  # a deep copy of plain JSON data
        if plain.moved:
            lon, lat, ele = layout.frame.back(plain.points)
            d = layout.digits
            at = 0
            for ln in (ln for ln in _lines(obj) if len(ln) >= 2):
                k = len(_open(ln))
                for j in range(k):
                    ln[j][0] = round(near(float(lon[at + j]), ln[j][0]), d)
                    ln[j][1] = round(float(lat[at + j]), d)
                    if ele is not None:
                        ln[j][2] = round(float(ele[at + j]), d)
                if k < len(ln):
                    ln[-1] = list(ln[0])
                at += k
    try:
        out.write(json.dumps(obj, allow_nan=False, separators=(",", ":")).encode("utf-8"))
    except ValueError as exc:
        raise FormatError(f"GeoJSON cannot hold {exc}", fmt="geojson") from None


def _fresh(plain: PlainDocument) -> dict[str, Any]:
    """GPX tracks as LineStrings in longitude/latitude(/elevation), one Feature each.

    Only geographic input reaches this (:func:`service.io.dispatch.check_output`).
    """
    frame = getattr(plain.layout, "frame", None)
    if not isinstance(frame, GeoFrame) or plain.dim not in (2, 3):
        raise FormatError(
            "GeoJSON holds longitude/latitude read from GPX or GeoJSON", fmt="geojson"
        )
    lon, lat, ele = frame.back(plain.points)
    digits = getattr(plain.layout, "digits", 9)  # the input's decimals (GPX: degrees, elevation)
    d, de = digits if isinstance(digits, tuple) else (digits, digits)
    cols = [np.round(lon, d), np.round(lat, d)] + ([] if ele is None else [np.round(ele, de)])
    pts = np.column_stack(cols).tolist()
    features = []
    for pl in plain.polylines:
        idx = pl.indices.tolist() + ([int(pl.indices[0])] if pl.closed else [])
        geom = {"type": "LineString", "coordinates": [pts[i] for i in idx]}
        features.append({"type": "Feature", "properties": {}, "geometry": geom})
    return {"type": "FeatureCollection", "features": features}
