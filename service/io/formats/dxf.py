"""DXF outlines via ezdxf: polylines, lines, arcs, circles, ellipses and splines in modelspace.

Reading
-------
``ezdxf.recover`` reads the drawing (ASCII or binary DXF, any version). Every LWPOLYLINE,
POLYLINE (2D and 3D; not polyface meshes), LINE, ARC, CIRCLE, ELLIPSE and SPLINE of the
modelspace becomes a point sequence (``ezdxf.path``; curves and bulges flattened to a sagitta of
1e-3 of the drawing's extent), and sequences whose ends meet (within 1e-9 of the extent) are
chained into polylines: ``wrench.dxf``'s 35 lines and 4 arcs become its two closed outlines.
Other entities (text, dimensions, hatches, block references) are kept as they are.

Writing
-------
The input drawing with each chain replaced: a chain that was one LWPOLYLINE or POLYLINE without
arcs keeps its entity (and all its attributes) with new vertices; other chains become one
LWPOLYLINE (2D, at the chain's elevation) or 3D POLYLINE on the first source entity's layer,
colour and linetype, and their source entities are deleted. Unchanged points give back the
input file byte for byte.

Documents of other formats get a new R2010 drawing in DXF's own idiom: faces as one ``MESH``
entity (shared vertices, every vertex in file order, double precision), polylines as
LWPOLYLINE (flat) or 3D POLYLINE, standalone edges as ``LINE`` entities, and points in no face or
line (a point cloud) as ``POINT`` entities.
"""

from __future__ import annotations

import io
import logging
from dataclasses import dataclass
from typing import Any, BinaryIO

import numpy as np
from numpy.typing import NDArray

from service.io._shared.assemble import assemble
from service.io._shared.plain import PlainDocument
from service.io.document import GeometryDocument, Precision
from service.io.errors import FormatError
from service.io.limits import InputTooLarge, ReadLimits, check_points, current
from service.io.source import Source

__all__ = ["DxfLayout", "read_dxf", "write_dxf"]

_KINDS = ("LWPOLYLINE", "POLYLINE", "LINE", "ARC", "CIRCLE", "ELLIPSE", "SPLINE")
#: Largest magnitude of any number of a supported entity (coordinates, radii, bulges, knots,
#: weights). ezdxf's geometry loops forever on NaN and on radii whose square overflows (a 71-byte
#: file with a NaN-centre circle or a 1e300 radius never finished parsing), so values are checked
#: before any geometry call. 1e12 keeps georeferenced drawings (1e7) with room to spare.
MAX_VALUE = 1e12
#: Points of all flattened entities together: a bound on the work of the flattening loop.
MAX_POINTS = 5_000_000
#: SPLINEs with more fit points (and no control points) are interpolated by :func:`_fit_spline`.
FIT_DENSE = 500


@dataclass(frozen=True, eq=False)
class DxfLayout:
    """The input's bytes and, per chain, its source entity handles and whether it is closed."""

    data: bytes
    chains: list[tuple[list[str], bool]]
    simple: list[bool]


#: ezdxf logs each value it recovers as a warning (up to 112 lines of a bad file on the CLI's
#: stderr, even with -q); what it could not recover is the one FormatError line.
logging.getLogger("ezdxf").setLevel(logging.ERROR)


def _load(data: bytes) -> Any:
    """The drawing ``ezdxf.recover`` makes of ``data``.

    Any exception of the recovery is the file's: besides ``DXFError`` and decoding errors, its
    audit of a damaged file raises ``AttributeError`` (a layout whose name did not decode) and
    ``AssertionError``; each is one FormatError line, never an internal error.
    """
    from ezdxf import recover
    from ezdxf.lldxf.const import DXFError

    try:
        doc, _ = recover.read(io.BytesIO(data))
    except MemoryError:
        raise
    except Exception as exc:
        text = " ".join(str(exc).split())[:200]
        if not isinstance(exc, DXFError | ValueError):
            text = f"the drawing is damaged beyond recovery ({type(exc).__name__}: {text})"
        raise FormatError(f"DXF: {text}", fmt="dxf") from None
    return doc


def _sequences(doc: Any) -> tuple[list[tuple[str, NDArray[np.float64], bool, bool]], float]:
    """(handle, points, closed, simple) of every supported entity, and the drawing's extent."""

    entities = [e for e in doc.modelspace() if e.dxftype() in _KINDS]
    entities = [e for e in entities if not (e.dxftype() == "POLYLINE" and not _plain_polyline(e))]
    for e in entities:
        _check_values(e)
    paths = []
    for e in entities:
        try:
            paths.append((e, _path(e)))
        except FormatError:  # the reader limits (a ValueError too)
            raise
        except (TypeError, ValueError):
            continue
    corners = np.array([v for _, p in paths for v in p.control_vertices()], dtype=np.float64)
    if not paths or corners.size == 0:
        raise FormatError("DXF modelspace has no lines, arcs or polylines", fmt="dxf")
    extent = float(np.max(np.ptp(corners, axis=0))) or 1.0
    if not (np.isfinite(corners).all() and np.isfinite(extent)):
        raise FormatError("DXF: an entity's geometry is not finite", fmt="dxf")
    out = []
    bound = current().max_points
    budget = start = MAX_POINTS if bound is None else min(MAX_POINTS, bound)
    for e, p in paths:
        pts = _flatten(e, p, 1e-3 * extent, budget, start - budget)
        budget -= len(pts)
        closed = _closed(e, p)
        if closed and len(pts) > 2 and np.allclose(pts[0], pts[-1], atol=1e-9 * extent):
            pts = pts[:-1]
        simple = e.dxftype() in ("LWPOLYLINE", "POLYLINE") and not _has_arcs(e)
        out.append((e.dxf.handle, pts, closed, simple))
    return out, extent


def _path(e: Any) -> Any:
    """``ezdxf.path.make_path``, except for SPLINEs given by many fit points only: ezdxf
    interpolates those with a dense (n+2) x (n+2) system (an 8.8 MB DXF with one 200,000-point
    SPLINE grew past 11.7 GB before it was killed); :func:`_fit_spline` solves the same
    interpolation as a banded system."""
    from ezdxf import path as ezpath
    from ezdxf.path import tools

    if e.dxftype() == "SPLINE" and not e.control_point_count():
        n = e.fit_point_count()
        check_points(n, 400, "dxf", "spline fit points")
        if n > FIT_DENSE:
            path = ezpath.Path()
            tools.add_spline(path, _fit_spline(e), level=4, reset=True)
            return path
    return ezpath.make_path(e)


def _fit_spline(e: Any) -> Any:
    """The cubic B-spline through a SPLINE's fit points as AutoCAD and ezdxf build it (chord
    length parameters on [0, 1], knots at the parameters, natural ends or the entity's end
    tangents scaled to the polygon's length: ``ezdxf.math.fit_points_to_cad_cv``), from
    scipy's banded solver: O(n) memory instead of ezdxf's O(n**2)."""
    from ezdxf.math import BSpline
    from scipy.interpolate import make_interp_spline

    pts = np.asarray([tuple(v) for v in e.fit_points], dtype=np.float64)
    keep = np.r_[True, np.any(pts[1:] != pts[:-1], axis=1)]
    pts = pts[keep]
    if len(pts) < 2:
        raise ValueError("a SPLINE needs two distinct fit points")
    steps = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    total = float(steps.sum())
    t = np.r_[0.0, np.cumsum(steps)] / total
    t[-1] = 1.0
    bc: Any = "natural"
    if e.dxf.hasattr("start_tangent") and e.dxf.hasattr("end_tangent"):
        names = ("start_tangent", "end_tangent")
        ends = [np.asarray(tuple(e.dxf.get(k)), dtype=np.float64) for k in names]
        norms = [float(np.linalg.norm(d)) for d in ends]
        if all(norms):
            d0, d1 = (total * d / m for d, m in zip(ends, norms, strict=True))
            bc = ([(1, d0)], [(1, d1)])
    curve = make_interp_spline(t, pts, k=3, bc_type=bc)
    return BSpline([tuple(c) for c in curve.c], order=4, knots=list(curve.t))


def _numbers(e: Any) -> list[float]:
    """Every number of an entity that its geometry depends on."""
    vals: list[float] = []
    for value in e.dxf.all_existing_dxf_attribs().values():
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            vals.append(float(value))
        elif hasattr(value, "__iter__") and not isinstance(value, str):
            vals.extend(float(x) for x in value if isinstance(x, (int, float)))
    kind = e.dxftype()
    if kind == "LWPOLYLINE":
        vals.extend(float(x) for row in e.get_points("xyseb") for x in row)
    elif kind == "POLYLINE":
        for v in e.vertices:
            vals.extend(float(x) for x in v.dxf.location)
            vals.append(float(v.dxf.get("bulge", 0.0)))
    elif kind == "SPLINE":
        for seq in (e.control_points, e.fit_points):
            vals.extend(float(x) for q in seq for x in q)
        vals.extend(float(x) for x in e.knots)
        vals.extend(float(x) for x in e.weights)
    return vals


def _check_values(e: Any) -> None:
    """:class:`FormatError` (naming the entity) for a non-finite or absurdly large number."""
    vals = np.asarray(_numbers(e), dtype=np.float64)
    bad = ~np.isfinite(vals) | (np.abs(vals) > MAX_VALUE)
    if bad.any():
        handle = e.dxf.get("handle", "?")
        raise FormatError(
            f"DXF: {e.dxftype()} (handle {handle}) has the value {float(vals[bad][0]):g}: "
            f"coordinates, radii and other numbers must be finite and at most {MAX_VALUE:g} "
            "in magnitude",
            fmt="dxf",
        )


def _flatten(e: Any, p: Any, sagitta: float, budget: int, done: int) -> NDArray[np.float64]:
    """The entity's path as points, stopping at ``budget`` points (then a FormatError: the
    reader limits' if ``done`` points before these exceed them)."""
    pts = []
    for v in p.flattening(sagitta):
        pts.append(tuple(v))
        if len(pts) > budget:
            if budget < MAX_POINTS - done:  # the reader limits' bound, not ours
                raise InputTooLarge(
                    f"DXF: the entities flatten to more than {done + budget} points (at "
                    f"{e.dxftype()} handle {e.dxf.get('handle', '?')}), the limit; "
                    f"{ReadLimits.HINT}",
                    fmt="dxf",
                )
            raise FormatError(
                f"DXF: the entities flatten to more than {MAX_POINTS} points "
                f"(at {e.dxftype()} handle {e.dxf.get('handle', '?')})",
                fmt="dxf",
            )
    return np.array(pts, dtype=np.float64).reshape(-1, 3)


def _closed(e: Any, p: Any) -> bool:
    kind = e.dxftype()
    if kind == "LWPOLYLINE":
        return bool(e.closed)
    if kind == "POLYLINE":
        return bool(e.is_closed)
    return kind == "CIRCLE" or (kind in ("ELLIPSE", "SPLINE") and bool(p.is_closed))


def _plain_polyline(e: Any) -> bool:
    return bool(e.is_2d_polyline or e.is_3d_polyline)


def _has_arcs(e: Any) -> bool:
    if e.dxftype() == "LWPOLYLINE":
        return any(abs(row[0]) > 0 for row in e.get_points("b"))
    return any(abs(v.dxf.get("bulge", 0)) > 0 for v in e.vertices)


def _chains(
    seqs: list[tuple[str, NDArray[np.float64], bool, bool]], tol: float
) -> list[tuple[list[str], NDArray[np.float64], bool, bool]]:
    """Join open sequences whose ends meet; closed ones stay as they are."""
    out = [([h], p, True, s) for h, p, c, s in seqs if c]
    open_ = [(h, p) for h, p, c, _ in seqs if not c and len(p) >= 2]
    used = [False] * len(open_)

    def key(v: NDArray[np.float64]) -> tuple[int, ...]:
        return tuple(np.round(v / tol).astype(np.int64).tolist())

    ends: dict[tuple[int, ...], list[tuple[int, int]]] = {}
    for i, (_, p) in enumerate(open_):
        ends.setdefault(key(p[0]), []).append((i, 0))
        ends.setdefault(key(p[-1]), []).append((i, 1))
    for i in range(len(open_)):
        if used[i]:
            continue
        used[i] = True
        handles, pts = [open_[i][0]], open_[i][1]
        for forward in (True, False):
            while True:
                tip = pts[-1] if forward else pts[0]
                nxt = next(((j, end) for j, end in ends.get(key(tip), []) if not used[j]), None)
                if nxt is None:
                    break
                j, end = nxt
                used[j] = True
                q = open_[j][1] if (end == 0) == forward else open_[j][1][::-1]
                pts = np.vstack([pts, q[1:]]) if forward else np.vstack([q[:-1], pts])
                handles = [*handles, open_[j][0]] if forward else [open_[j][0], *handles]
        closed = len(pts) > 2 and key(pts[0]) == key(pts[-1])
        simple = len(handles) == 1 and any(h == handles[0] and s for h, _, _, s in seqs)
        out.append((handles, pts[:-1] if closed else pts, closed, simple))
    return out


def read_dxf(source: Source, *, weld: bool = False) -> GeometryDocument:
    """Read the outlines of a DXF drawing (see the module docstring)."""
    data = source.data()
    if not data.strip():
        raise FormatError("the file is empty", fmt="dxf")
    doc = _load(data)
    seqs, extent = _sequences(doc)
    chains = [c for c in _chains(seqs, 1e-9 * extent) if len(c[1])]
    if not chains:
        raise FormatError("DXF modelspace has no lines, arcs or polylines", fmt="dxf")
    pts = np.concatenate([c[1] for c in chains])
    flat = pts[:, 2] if np.all(pts[:, 2] == pts[0, 2]) else None
    points = pts[:, :2] if flat is not None else pts
    polylines = []
    at = 0
    for _, p, closed, _ in chains:
        polylines.append((np.arange(at, at + len(p)), closed))
        at += len(p)
    notes = [f"{len(seqs)} DXF entities chained into {len(chains)} polylines"]
    layout = DxfLayout(data, [(h, c) for h, _, c, _ in chains], [c[3] for c in chains])
    result = assemble(points, fmt="dxf", polylines=polylines, notes=notes, weld=weld)
    return result.with_extras(layout=layout, precision=Precision("float64"))


def write_dxf(plain: PlainDocument, out: BinaryIO) -> None:
    """Write a plain document as DXF (see the module docstring)."""
    layout = plain.layout
    if isinstance(layout, DxfLayout) and not plain.moved:
        out.write(layout.data)
        return
    pts = plain.points if plain.dim == 3 else np.column_stack([plain.points, np.zeros(plain.n)])
    if isinstance(layout, DxfLayout):
        doc = _load(layout.data)
        msp = doc.modelspace()
        groups = [pl.indices for pl in plain.polylines]
        for (handles, closed), idx, keep in zip(layout.chains, groups, layout.simple, strict=True):
            _replace(doc, msp, handles, pts[idx], closed, keep)
    else:
        doc = _fresh(plain, pts)
        if plain.georef is not None:
            _georef(doc, plain.georef)
    text = io.StringIO()
    doc.write(text)
    out.write(text.getvalue().encode(doc.output_encoding, errors="replace"))


def _replace(
    doc: Any, msp: Any, handles: list[str], p: NDArray[np.float64], closed: bool, keep: bool
) -> None:
    first = doc.entitydb.get(handles[0]) if handles else None
    flat = bool(np.all(p[:, 2] == p[0, 2]))
    if keep and first is not None and first.dxftype() == "LWPOLYLINE":
        rows = list(first.get_points("xyseb"))
        first.set_points(
            [(x, y, *rest[2:]) for (x, y), rest in zip(p[:, :2].tolist(), rows, strict=True)],
            format="xyseb",
        )
        return
    if keep and first is not None and first.dxftype() == "POLYLINE":
        for v, q in zip(first.vertices, p.tolist(), strict=True):
            v.dxf.location = q if first.is_3d_polyline else (q[0], q[1], v.dxf.location.z)
        return
    attribs = {}
    if first is not None:
        attribs = {
            k: first.dxf.get(k) for k in ("layer", "color", "linetype") if first.dxf.hasattr(k)
        }
    if flat and doc.dxfversion >= "AC1015":  # LWPOLYLINE needs R2000; an R12 file: POLYLINE
        msp.add_lwpolyline(
            p[:, :2].tolist(), close=closed, dxfattribs={**attribs, "elevation": float(p[0, 2])}
        )
    else:
        msp.add_polyline3d(p.tolist(), close=closed, dxfattribs=attribs)
    for h in handles:
        e = doc.entitydb.get(h)
        if e is not None:
            msp.delete_entity(e)


def _georef(doc: Any, georef: Any) -> None:
    """The frame of the coordinates: origin in ``$LATITUDE``/``$LONGITUDE``, the CRS and the
    frame's description in the custom properties ``CRS`` and ``CRS_FRAME``."""
    doc.header["$LONGITUDE"] = float(georef.origin[0])
    doc.header["$LATITUDE"] = float(georef.origin[1])
    doc.header.custom_vars.append("CRS", georef.crs)
    doc.header.custom_vars.append("CRS_FRAME", "; ".join(georef.lines()))


def _fresh(plain: PlainDocument, pts: NDArray[np.float64]) -> Any:
    """A new drawing: MESH for faces, polylines, LINEs, POINTs for the rest (see the docstring)."""
    import ezdxf

    doc = ezdxf.new("R2010")
    msp = doc.modelspace()
    used = np.zeros(plain.n, dtype=bool)
    if plain.faces is not None and len(plain.faces):
        mesh = msp.add_mesh()
        with mesh.edit_data() as data:
            data.vertices = pts.tolist()
            data.faces = np.asarray(plain.faces).tolist()
        used[:] = True
    for pl in plain.polylines:
        _replace(doc, msp, [], pts[pl.indices], pl.closed, False)
        used[pl.indices] = True
    if plain.standalone_edges is not None:
        for a, b in np.asarray(plain.standalone_edges).tolist():
            msp.add_line(pts[a].tolist(), pts[b].tolist())
        used[np.asarray(plain.standalone_edges).reshape(-1)] = True
    for i in np.flatnonzero(~used).tolist():
        msp.add_point(pts[i].tolist())
    return doc
