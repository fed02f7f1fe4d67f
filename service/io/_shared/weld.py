"""Welding: merge vertices with exactly identical coordinates.

Files such as ``featuretype.ply`` store one vertex per (position, normal) pair, so a closed CAD
part looks like thousands of loose triangles (5096 vertices, 1722 distinct positions). Welding
merges vertices whose coordinates are bit-identical (``-0.0`` equals ``0.0``; no tolerance):

* welded vertices are numbered in order of first occurrence in the file;
* faces, standalone edges and polylines are remapped; faces and edges that now repeat a vertex
  are dropped (noted); polylines have consecutive repeats collapsed;
* weights: a welded vertex gets the mean weight of the vertices merged into it (``+inf``, i.e.
  fixed, if any of them is fixed); fixed indices are mapped to their welded vertex.

The document keeps a :class:`~service.io.document.WeldMap`, so writers emit the file's original
vertex count, order and connectivity, each original vertex taking the position of its welded
vertex.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from service.core.geometry import Geometry
from service.io._shared.elements import drop_repeating, edge_array, normalize_polyline
from service.io.document import GeometryDocument, Polyline, WeldMap

__all__ = ["weld_document", "weld_if_tied", "weld_index"]


_NEG_ZERO = np.uint64(1 << 63)
_MIX = (np.uint64(0x9E3779B97F4A7C15), np.uint64(0xC2B2AE3D27D4EB4F), np.uint64(0x165667B19E3779F9))


def _hash_groups(
    pts: NDArray[np.float64],
) -> tuple[NDArray[np.int64] | None, NDArray[np.bool_]]:
    """Order of the rows by a 64-bit hash of their bits (-0.0 as 0.0; a stable radix sort), and
    where a new group starts; ``None`` if two different rows share a hash."""
    n, s = pts.shape
    bits = pts.view(np.uint64)
    h = np.zeros(n, dtype=np.uint64)
    with np.errstate(over="ignore"):
        for j in range(s):
            col = np.where(bits[:, j] == _NEG_ZERO, np.uint64(0), bits[:, j])
            h = (h ^ col) * _MIX[j % 3]
            h ^= h >> np.uint64(29)
    order = np.argsort(h, kind="stable")
    hs = h[order]
    new = np.empty(n, dtype=bool)
    new[:1] = True
    np.not_equal(hs[1:], hs[:-1], out=new[1:])
    dup = np.flatnonzero(~new[1:]) + 1
    if dup.size and np.any(pts[order[dup]] != pts[order[dup - 1]]):
        return None, new
    return order.astype(np.int64), new


def weld_index(points: NDArray[np.float64]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Group identical rows.

    Returns
    -------
    index : ndarray of int, shape (n,)
        Welded vertex of each point; welded vertices numbered by first occurrence.
    first : ndarray of int, shape (n_welded,)
        The first original point of each welded vertex.
    """
    pts = np.ascontiguousarray(points, dtype=np.float64)
    n = pts.shape[0]
    order, new = _hash_groups(pts)
    if order is None:  # a hash collision (never seen): sort the coordinates themselves
        order = np.lexsort(pts.T[::-1])  # stable; -0.0 and 0.0 compare (and sort) equal
        srt = pts[order]
        new = np.empty(n, dtype=bool)
        new[:1] = True
        np.any(srt[1:] != srt[:-1], axis=1, out=new[1:])
        del srt
    group = np.cumsum(new) - 1  # group of each point, in sorted order
    first = order[np.flatnonzero(new)]  # stable sort: the first occurrence leads its group
    by_first = np.argsort(first, kind="stable")
    rank = np.empty_like(by_first)
    rank[by_first] = np.arange(by_first.size)
    index = np.empty(n, dtype=np.int64)
    index[order] = rank[group]
    return index, first[by_first].astype(np.int64)


def weld_if_tied(doc: GeometryDocument) -> GeometryDocument:
    """``doc`` welded when faces use two vertices at one position (issue 31): smoothed apart,
    the copies of one vertex tear the surface open (``featuretype.ply`` with ``rms 0.01``:
    copies 0.207 apart). Clouds, curves and meshes without such duplicates stay as read."""
    g = doc.geometry
    if doc.weld is not None or g.faces is None:
        return doc
    index, first = weld_index(g.points)
    if first.size == g.n:
        return doc
    used = np.zeros(g.n, dtype=bool)
    used[g.faces.ravel()] = True
    tied = np.bincount(index[used], minlength=first.size) > 1
    if not tied.any():
        return doc
    out = weld_document(doc)
    note = (
        f"{g.n - first.size} duplicate positions tie faces: welded by default (the output "
        "keeps the file's vertex count and order; copies of a vertex stay identical; "
        "weld=False keeps them apart)"
    )
    return out.with_extras(notes=[*out.notes, note])


def _welded_connectivity(
    doc: GeometryDocument, index: NDArray[np.int64], notes: list[str]
) -> tuple[NDArray[np.int64] | None, NDArray[np.int64] | None, list[Polyline]]:
    """Faces, standalone edges and polylines of ``doc`` on the welded vertices ``index``,
    without those that became degenerate (a note for each kind dropped)."""
    g = doc.geometry
    faces = None
    if g.faces is not None:
        faces, n_rep = drop_repeating(index[g.faces])
        if n_rep:
            notes.append(f"dropped {n_rep} faces that became degenerate after welding")
    standalone = None
    if doc.standalone_edges is not None:
        standalone, n_rep = drop_repeating(index[doc.standalone_edges])
        if n_rep:
            notes.append(f"dropped {n_rep} edges that became degenerate after welding")
    polylines: list[Polyline] = []
    for pl in doc.polylines:
        new = normalize_polyline(index[pl.indices], pl.closed)
        if new is not None:
            polylines.append(new)
    if len(polylines) < len(doc.polylines):
        notes.append(
            f"dropped {len(doc.polylines) - len(polylines)} polylines that collapsed to a point"
            " after welding"
        )
    return faces, standalone, polylines


def weld_document(doc: GeometryDocument) -> GeometryDocument:
    """Weld exactly coincident vertices of ``doc`` (which must not be welded already)."""
    if doc.weld is not None:
        return doc
    g = doc.geometry
    index, first = weld_index(g.points)
    notes = list(doc.notes)
    if first.size == g.n:
        notes.append(f"welding: all {g.n} vertices are distinct")
    else:
        notes.append(f"welded {g.n} vertices to {first.size} distinct positions")
    faces, standalone, polylines = _welded_connectivity(doc, index, notes)
    weights = None
    if g.weights is not None:
        counts = np.bincount(index, minlength=first.size)
        weights = np.bincount(index, weights=g.weights, minlength=first.size) / counts
    fixed = np.unique(index[g.fixed]) if g.fixed is not None else None
    welded = Geometry(
        g.points[first],
        faces=faces,
        edges=edge_array(standalone, polylines),
        weights=weights,
        fixed=fixed,
    )
    weld = WeldMap(
        index=index,
        faces=g.faces,
        standalone_edges=doc.standalone_edges,
        polylines=list(doc.polylines),
        weights=g.weights,
        fixed=g.fixed,
    )
    return GeometryDocument(
        geometry=welded,
        polylines=polylines,
        source_format=doc.source_format,
        standalone_edges=standalone if standalone is not None and len(standalone) else None,
        notes=notes,
        weld=weld,
        comments=list(doc.comments),
    )
