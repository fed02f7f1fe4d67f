"""Turn parsed arrays into a :class:`GeometryDocument` (the last step of every reader).

Readers check index ranges themselves (they know line numbers); this module applies the shared
clean-up rules of :mod:`service.io._shared.elements`, records what it dropped in the notes, builds
the
validated :class:`~service.core.geometry.Geometry` and welds on request.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from service.core.frame import Frame
from service.core.geometry import Geometry
from service.io._shared.elements import (
    drop_repeating,
    edge_array,
    fan_triangulate,
    normalize_polyline,
)
from service.io._shared.weld import weld_document
from service.io.document import GeometryDocument, Polyline
from service.io.errors import FormatError

__all__ = ["assemble", "require_points", "triangles"]


def _plural(k: int, word: str) -> str:
    return f"{k} {word}" if k == 1 else f"{k} {word}s"


def require_points(points: NDArray[np.float64], fmt: str) -> None:
    """:class:`FormatError` for a file without points (every reader, both paths)."""
    if points.ndim != 2 or points.shape[0] == 0:
        raise FormatError("the file holds no points", fmt=fmt)


def triangles(
    polygons: tuple[NDArray[np.int64], NDArray[np.int64]],
) -> tuple[NDArray[np.int64], list[str]]:
    """Polygons (flat indices, counts) fan-triangulated, triangles repeating a vertex dropped;
    and the notes saying what was dropped (the ordinary and the streamed readers)."""
    notes = []
    faces, n_small = fan_triangulate(*polygons)
    if n_small:
        notes.append(f"dropped {_plural(n_small, 'face')} with fewer than 3 vertices")
    faces, n_rep = drop_repeating(faces)
    if n_rep:
        notes.append(f"dropped {_plural(n_rep, 'triangle')} that repeat a vertex")
    return faces, notes


def assemble(
    points: NDArray[np.float64],
    *,
    fmt: str,
    polygons: tuple[NDArray[np.int64], NDArray[np.int64]] | None = None,
    edges: NDArray[np.int64] | None = None,
    polylines: Sequence[tuple[NDArray[np.int64], bool]] = (),
    weights: NDArray[np.float64] | None = None,
    fixed: NDArray[np.int64] | None = None,
    notes: list[str] | None = None,
    comments: list[str] | None = None,
    weld: bool = False,
) -> GeometryDocument:
    """Build a document from in-range, 0-based connectivity.

    Parameters
    ----------
    points : ndarray, shape (n, s)
        Coordinates as read.
    fmt : str
        Format name (for errors and ``source_format``).
    polygons : (flat, counts), optional
        Faces as concatenated vertex indices and per-face vertex counts; fan-triangulated.
    edges : ndarray of int, shape (k, 2), optional
        Standalone edges.
    polylines : sequence of (indices, closed)
        Polylines; a repeated first index at the end also closes a polyline.
    weights, fixed : optional
        Per-point weights and fixed indices (JSON only).
    notes : list of str, optional
        Notes collected by the reader; extended here.
    comments : list of str, optional
        Header comments to carry to the written file.
    weld : bool
        Merge exactly coincident vertices (see :func:`service.io._shared.weld.weld_document`).

    Raises
    ------
    FormatError
        If there are no points.
    GeometryError
        From :class:`Geometry` validation (e.g. non-finite coordinates), or points spanning
        more than the engine represents (:meth:`~service.core.frame.Frame.of`: a GPX
        elevation of 1e308 reached the noise estimate and failed there as an internal error).
    """
    notes = list(notes or [])
    pts = np.asarray(points, dtype=np.float64)
    require_points(pts, fmt)
    faces = None
    if polygons is not None:
        faces, dropped = triangles(polygons)
        notes.extend(dropped)
    standalone = _standalone_edges(edges, notes)
    lines = _polylines(polylines, notes)
    all_edges = edge_array(standalone, lines)
    geometry = Geometry(pts, faces=faces, edges=all_edges, weights=weights, fixed=fixed)
    Frame.of(geometry.points, "normalized")  # the engine's extent check, at the read (issue 42)
    doc = GeometryDocument(
        geometry=geometry,
        polylines=lines,
        source_format=fmt,
        standalone_edges=standalone,
        notes=notes,
        comments=list(comments or []),
    )
    return weld_document(doc) if weld else doc


def _standalone_edges(
    edges: NDArray[np.int64] | None, notes: list[str]
) -> NDArray[np.int64] | None:
    """The edges that join two distinct vertices (``None``: none); a note for those dropped."""
    if edges is None or not len(edges):
        return None
    standalone, n_rep = drop_repeating(np.asarray(edges, dtype=np.int64).reshape(-1, 2))
    if n_rep:
        notes.append(f"dropped {_plural(n_rep, 'edge')} that repeat a vertex")
    return standalone if len(standalone) else None


def _polylines(
    polylines: Sequence[tuple[NDArray[np.int64], bool]], notes: list[str]
) -> list[Polyline]:
    """The polylines of at least 2 distinct vertices, normalized; a note for those dropped."""
    lines: list[Polyline] = []
    n_short = 0
    for idx, closed in polylines:
        pl = normalize_polyline(idx, closed)
        if pl is None:
            n_short += 1
        else:
            lines.append(pl)
    if n_short:
        notes.append(f"dropped {_plural(n_short, 'polyline')} with fewer than 2 distinct vertices")
    return lines
