"""GPX tracks and routes via gpxpy, smoothed in metres.

Reading
-------
Each track segment and each route with two or more points is a polyline. Coordinates go to the
local east/north/up frame about the data's centre (:mod:`.geodata`), with the elevation as
height when every point has one, so ``rms=3`` means 3 m; ``geographic=False`` smooths the raw
degrees instead. Waypoints, times, names, extensions and everything else stay in the gpxpy tree
(the layout) and are not smoothed.

Writing
-------
The input file with new latitude, longitude (and elevation) numbers spliced in place, rounded to
the decimals the input used, every other byte unchanged (output size = input size). Should the
point elements not be matched one to one, gpxpy writes the tree instead. GeoJSON lines become
one track (a segment per line); planar input is refused before smoothing (GPX holds
longitude/latitude only).
"""

from __future__ import annotations

import copy
import re
from dataclasses import dataclass
from typing import Any, BinaryIO

import numpy as np

from service.io._shared.assemble import assemble
from service.io._shared.geodata import GeoFrame, decimals, near
from service.io._shared.plain import PlainDocument
from service.io.document import GeometryDocument, Precision
from service.io.errors import FormatError
from service.io.source import Source

__all__ = ["GpxLayout", "read_gpx", "write_gpx"]

_ATTR = re.compile(rb'\b(lat|lon)\s*=\s*["\']([^"\']*)["\']')
_ELE = re.compile(rb"<ele>\s*([^<\s]*)\s*</ele>")


@dataclass(frozen=True, eq=False)
class GpxLayout:
    """The parsed GPX, its frame, and the decimals of coordinates and elevations."""

    gpx: Any
    frame: GeoFrame
    digits: tuple[int, int]
    data: bytes


def _lines(gpx: Any) -> list[list[Any]]:
    out = [seg.points for trk in gpx.tracks for seg in trk.segments]
    out += [rte.points for rte in gpx.routes]
    return [pts for pts in out if len(pts) >= 2]


def _parse(data: bytes) -> Any:
    import gpxpy
    import gpxpy.gpx

    try:
        return gpxpy.parse(data.decode("utf-8"))
    except UnicodeDecodeError:
        raise FormatError("GPX is not UTF-8 text", fmt="gpx") from None
    except (gpxpy.gpx.GPXException, ValueError) as exc:
        raise FormatError(f"GPX: {' '.join(str(exc).split())[:200]}", fmt="gpx") from None


def read_gpx(source: Source, *, weld: bool = False, geographic: bool = True) -> GeometryDocument:
    """Read the tracks and routes of a GPX file (see the module docstring)."""
    data = source.data()
    if not data.strip():
        raise FormatError("the file is empty", fmt="gpx")
    gpx = _parse(data)
    lines = _lines(gpx)
    if not lines:
        raise FormatError("GPX has no track segment or route with two or more points", fmt="gpx")
    flat = [p for pts in lines for p in pts]
    lat = np.array([p.latitude for p in flat], dtype=np.float64)
    lon = np.array([p.longitude for p in flat], dtype=np.float64)
    has_ele = all(p.elevation is not None for p in flat)
    ele = np.array([p.elevation if has_ele else 0.0 for p in flat], dtype=np.float64)
    frame = GeoFrame.of(lon, lat, has_ele, geographic)
    points = frame.points(lon, lat, ele)
    ends = np.cumsum([len(pts) for pts in lines])
    polylines = [(np.arange(e - len(pts), e), False) for pts, e in zip(lines, ends, strict=True)]
    coord_digits = decimals([m[2].decode() for m in _ATTR.finditer(data)])
    ele_digits = decimals([m[1].decode() for m in _ELE.finditer(data)], default=3)
    notes = [
        f"{len(lines)} track segments/routes, {len(flat)} points"
        + (" smoothed in metres (local east/north/up frame)" if geographic else " (degrees)")
    ]
    if gpx.waypoints:
        notes.append(f"kept {len(gpx.waypoints)} waypoints as they are")
    layout = GpxLayout(gpx, frame, (coord_digits, ele_digits), data)
    doc = assemble(points, fmt="gpx", polylines=polylines, notes=notes, weld=weld)
    return doc.with_extras(layout=layout, precision=Precision("float64"))


_POINT = re.compile(rb"<(trkpt|rtept)\b[^>]*?(/?)>")


def _spans(data: bytes) -> dict[bytes, list[tuple[int, int]]]:
    """Byte spans of every ``trkpt`` / ``rtept`` element, in document order, per kind."""
    out: dict[bytes, list[tuple[int, int]]] = {b"trkpt": [], b"rtept": []}
    for m in _POINT.finditer(data):
        kind = m[1]
        end = m.end() if m[2] else data.find(b"</" + kind, m.end())
        out[kind].append((m.start(), end if end >= 0 else m.end()))
    return out


def _splice(data: bytes, gpx: Any, plain: PlainDocument, layout: GpxLayout) -> bytes | None:
    """The input bytes with new numbers in place, or None if the elements cannot be matched."""
    spans = _spans(data)
    every = [(b"trkpt", p) for trk in gpx.tracks for seg in trk.segments for p in seg.points]
    every += [(b"rtept", p) for rte in gpx.routes for p in rte.points]
    if len(spans[b"trkpt"]) + len(spans[b"rtept"]) != len(every):
        return None
    where = {id(p): spans[k][i] for (k, p), i in zip(every, _ranks(every), strict=True)}
    used = [p for pts in _lines(gpx) for p in pts]
    lon, lat, ele = layout.frame.back(plain.points)
    cd, ed = layout.digits
    edits: list[tuple[int, int, bytes]] = []
    for i, p in enumerate(used):
        start, end = where[id(p)]
        head = data[start:end]
        for m in _ATTR.finditer(head[: head.find(b">") + 1]):
            value = lat[i] if m[1] == b"lat" else near(float(lon[i]), p.longitude)
            edits.append((start + m.start(2), start + m.end(2), f"{value:.{cd}f}".encode()))
        e = _ELE.search(head)
        if ele is not None and e is not None:
            edits.append((start + e.start(1), start + e.end(1), f"{ele[i]:.{ed}f}".encode()))
    parts, pos = [], 0
    for a, b, text in sorted(edits):
        parts += [data[pos:a], text]
        pos = b
    parts.append(data[pos:])
    return b"".join(parts)


def _ranks(every: list[tuple[bytes, Any]]) -> list[int]:
    seen = {b"trkpt": 0, b"rtept": 0}
    out = []
    for kind, _ in every:
        out.append(seen[kind])
        seen[kind] += 1
    return out


def write_gpx(plain: PlainDocument, out: BinaryIO) -> None:
    """Write a plain document as GPX: the input with new coordinates (see the docstring)."""
    layout = plain.layout
    if not isinstance(layout, GpxLayout):
        return _fresh(plain, out)
    if sum(len(pts) for pts in _lines(layout.gpx)) != plain.n:
        raise FormatError("the points do not match the GPX tracks they were read from", fmt="gpx")
    if not plain.moved:
        out.write(layout.data)
        return None
    spliced = _splice(layout.data, layout.gpx, plain, layout)
    if spliced is not None:
        out.write(spliced)
        return None
    gpx = copy.deepcopy(layout.gpx)  # elements we could not match: let gpxpy write the tree
    lon, lat, ele = layout.frame.back(plain.points)
    cd, ed = layout.digits
    for i, p in enumerate(p for pts in _lines(gpx) for p in pts):
        p.latitude = round(float(lat[i]), cd)
        p.longitude = round(near(float(lon[i]), p.longitude), cd)
        if ele is not None:
            p.elevation = round(float(ele[i]), ed)
    out.write(gpx.to_xml(version=gpx.version).encode("utf-8"))
    return None


def _fresh(plain: PlainDocument, out: BinaryIO) -> None:
    """A GeoJSON document as one track: a segment per polyline (closed ones end where they start).

    Only geographic input reaches this (:func:`service.io.dispatch.check_output`): the points go
    back to longitude/latitude/elevation through the frame they were read with.
    """
    import gpxpy.gpx

    frame = getattr(plain.layout, "frame", None)
    if not isinstance(frame, GeoFrame) or plain.dim not in (2, 3):
        raise FormatError("GPX holds longitude/latitude read from GPX or GeoJSON", fmt="gpx")
    lon, lat, ele = frame.back(plain.points)
    gpx = gpxpy.gpx.GPX()
    track = gpxpy.gpx.GPXTrack()
    gpx.tracks.append(track)
    for pl in plain.polylines:
        seg = gpxpy.gpx.GPXTrackSegment()
        idx = pl.indices.tolist() + ([int(pl.indices[0])] if pl.closed else [])
        for i in idx:
            h = None if ele is None else float(ele[i])
            seg.points.append(gpxpy.gpx.GPXTrackPoint(float(lat[i]), float(lon[i]), elevation=h))
        track.segments.append(seg)
    out.write(gpx.to_xml().encode("utf-8"))
