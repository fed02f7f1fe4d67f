"""What an output format holds of a document, and the notes naming what it does not.

:func:`input_kinds` says what writing a document needs (faces, lines, points); a format that
holds points (``"cloud"`` in its registry ``kinds``) but not the input's faces or lines writes
the vertices as points, with a note (:func:`dropped_kinds`), as PDAL and CloudCompare do;
:func:`output_notes` names every attribute the output cannot hold (colours, extra columns,
texture coordinates) and where georeferenced input goes; :func:`georeference` records that frame
in the written document, or projects to the ``crs`` option (the frames themselves:
:mod:`service.io._shared.georef`).
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

from service.io._shared.georef import CrsOption, Georef, project, reproject, target_crs

if TYPE_CHECKING:
    from service.io._shared.plain import PlainDocument
    from service.io.document import GeometryDocument
    from service.io.registry import Format

__all__ = [
    "crs_notes",
    "dropped_kinds",
    "georeference",
    "input_kinds",
    "is_geographic",
    "output_notes",
    "same_family",
    "source_crs",
    "uv_count",
]

_LOST = {"mesh": "faces", "polyline": "lines"}


def input_kinds(doc: GeometryDocument) -> frozenset[str]:
    """What writing ``doc`` needs: ``"mesh"`` (faces), ``"polyline"`` (edges), else ``"cloud"``."""
    g = doc.geometry
    kinds = set()
    if g.faces is not None and len(g.faces):
        kinds.add("mesh")
    if g.edges is not None and len(g.edges):
        kinds.add("polyline")
    return frozenset(kinds or {"cloud"})


def same_family(doc: GeometryDocument, spec: Format) -> bool:
    """Whether the writer gets the input's own layout (the file written back in its format)."""
    source = doc.source_format
    return source == spec.name or {source, spec.name} == {"las", "laz"}


def dropped_kinds(doc: GeometryDocument, spec: Format) -> list[str]:
    """Connectivity ``spec`` writes without: the input's faces/lines when it holds points only.

    Empty when ``spec`` holds all of the input, or when it holds no points either (then the
    output is refused, see :func:`service.io.dispatch.check_output`).
    """
    if same_family(doc, spec) or "cloud" not in spec.kinds:
        return []
    return sorted(k for k in input_kinds(doc) - spec.kinds if k != "cloud")


def is_geographic(doc: GeometryDocument) -> bool:
    """Whether ``doc`` holds longitude/latitude read from a geographic format (GPX, GeoJSON)."""
    frame = getattr(doc.layout, "frame", None)
    if frame is None or not hasattr(frame, "back"):
        return False
    if frame.frame is not None or doc.source_format == "gpx":
        return True
    from service.io.formats.geojson import _geographic

    pts = doc.geometry.points
    return pts.shape[1] >= 2 and _geographic(doc.layout.obj, pts[:, 0], pts[:, 1], None)  # type: ignore[attr-defined]


def uv_count(doc: GeometryDocument) -> int:
    """Texture coordinates of an OBJ input (its ``vt`` lines; glTF's are the ``uv`` attribute,
    named with the other attributes)."""
    data = getattr(doc.layout, "data", None)
    if doc.source_format != "obj" or not isinstance(data, bytes):
        return 0
    return data.count(b"\nvt ") + data.startswith(b"vt ")


def output_notes(doc: GeometryDocument, fmt: str, crs: str | int | None = None) -> list[str]:
    """The reader's notes that stay true for a file written in ``fmt``, and what it drops
    (``crs``: the writer option of :func:`service.io.write_geometry`)."""
    from service.io.registry import get_format

    spec = get_format(fmt)
    if same_family(doc, spec):
        return list(doc.notes) + crs_notes(doc, spec, crs)
    lost = [name for name in doc.attributes if not spec.keeps(name)]
    notes = [n for n in doc.notes if not (lost and n.startswith("kept ") and "column" in n)]
    notes = [n for n in notes if not n.endswith("waypoints as they are")] + _gpx_notes(doc, spec)
    if lost:
        notes.append(f"{spec.title} keeps no {', '.join(lost)}: not written")
    from service.io._shared.texture import keeps_uv

    uvs = uv_count(doc)
    if uvs and not keeps_uv(doc, spec.name):
        notes.append(f"{spec.title} output keeps no texture coordinates: {uvs} UVs not written")
    dropped = dropped_kinds(doc, spec)
    if dropped:
        what = " or ".join(_LOST[k] for k in dropped)
        notes.append(f"{spec.title} keeps no {what}: wrote the {doc.n_output} vertices as points")
    frame = getattr(getattr(doc.layout, "frame", None), "frame", None)
    if crs is not None:
        notes += crs_notes(doc, spec, crs)
    elif frame is not None and not spec.geographic_only:  # metres about the data's centre
        notes.append(
            f"{spec.title} gets metres in the local east/north/up frame about the data's centre,"
            " not longitude/latitude (write GPX or GeoJSON to keep them)"
        )
    return notes


def source_crs(doc: GeometryDocument) -> object | None:
    """The ``pyproj.CRS`` a planar input declares (a LAS/LAZ CRS record), else ``None``."""
    header = getattr(doc.layout, "header", None)
    if header is None or not hasattr(header, "parse_crs"):
        return None
    from service.io.formats.las_meta import file_crs

    return file_crs(header)


def _gpx_notes(doc: GeometryDocument, spec: Format) -> list[str]:
    """What a GPX input loses in another format: its waypoints and its points' times (issue
    41: a LAS's gps_time is 0 for them, so say so)."""
    gpx = getattr(doc.layout, "gpx", None)
    if gpx is None or doc.source_format != "gpx":
        return []
    out = []
    if gpx.waypoints:
        out.append(f"{spec.title} keeps no GPX waypoints: {len(gpx.waypoints)} not written")
    points = [p for trk in gpx.tracks for seg in trk.segments for p in seg.points]
    points += [p for rte in gpx.routes for p in rte.points]
    timed = sum(p.time is not None for p in points)
    if timed:
        out.append(f"{spec.title} gets no GPX times: the <time> of {timed} points not written")
    return out


def crs_notes(doc: GeometryDocument, spec: Format, crs: CrsOption) -> list[str]:
    """The note naming the resolved EPSG of the ``crs`` option (``utm``: the zone chosen)."""
    if crs is None or spec.geographic_only:
        return []
    frame = getattr(getattr(doc.layout, "frame", None), "frame", None)
    try:
        import pyproj

        if frame is not None:
            target = target_crs(crs, frame)
            name = pyproj.CRS.from_user_input(target).name
            return [f"{spec.title} gets easting/northing in {target} ({name}), not "
                    "longitude/latitude"]  # fmt: skip
        source = source_crs(doc)
        if source is None:
            return []
        import numpy as np

        pts = doc.geometry.points
        _, georef = reproject(source, crs, np.vstack([pts.min(axis=0), pts.max(axis=0)]))
    except (ValueError, pyproj.exceptions.CRSError):
        return []
    code = source.to_epsg()  # type: ignore[attr-defined]
    was = f"EPSG:{code}" if code else str(source.name)  # type: ignore[attr-defined]
    return [f"{spec.title} reprojected from {was} to {georef.crs} ({georef.name})"]


def georeference(
    doc: GeometryDocument, spec: Format, plain: PlainDocument, option: CrsOption
) -> PlainDocument:
    """``plain`` with its frame recorded, and projected to the ``crs`` option if given.

    Raises
    ------
    ValueError
        ``crs`` given for input that is not geographic, for a longitude/latitude output, or not
        a projected EPSG CRS.
    """
    geo = getattr(doc.layout, "frame", None)
    frame = getattr(geo, "frame", None)
    source = None if frame is not None or option is None else source_crs(doc)
    if source is not None and not spec.geographic_only:  # projected input: issue 41
        pts, georef = reproject(source, option, plain.points)
        return replace(plain, points=pts, normals=None, georef=georef, moved=True)
    if option is not None and (frame is None or spec.geographic_only or same_family(doc, spec)):
        where = "longitude/latitude" if spec.geographic_only else "planar coordinates"
        raise ValueError(
            "crs applies to input whose CRS is known (a LAS/LAZ CRS record, or geographic input:"
            f" GPX, GeoJSON) written to a projected format; this {spec.title} output gets {where}"
        )
    if frame is None or spec.geographic_only or same_family(doc, spec):
        return plain
    assert geo is not None
    origin = (frame.lon0, frame.lat0, 0.0)
    if option is None:
        name = "geosmooth local east/north/up metres"
        return replace(plain, georef=Georef("local", origin, name))
    target = target_crs(option, frame)
    lon, lat, ele = geo.back(plain.points)
    pts, name = project(target, lon, lat, ele)
    return replace(plain, points=pts, normals=None, georef=Georef(target, origin, name))
