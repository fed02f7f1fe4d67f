"""What a reader returns: :class:`GeometryDocument`, :class:`Polyline`, :class:`WeldMap`.

A document wraps the validated :class:`~service.core.geometry.Geometry` the engine smooths, plus
everything needed to write the result back in the input's shape:

* ``polylines``: OBJ ``l`` elements, GPX segments, GeoJSON/DXF lines, JSON ``polylines``, in
  geometry indexing. Their edges are part of ``geometry.edges``.
* ``standalone_edges``: edges that belong to no polyline (PLY ``edge``, JSON ``edges``).
  ``geometry.edges`` is these followed by the polyline edges.
* ``weld``: set when the file was read with ``weld=True``. The geometry then holds one vertex per
  distinct position and :attr:`WeldMap.index` maps every vertex of the file to its welded vertex.
  Writers never see it: :func:`service.io._shared.plain.plain_document` expands the document back
  to the
  file's vertices once, before writing.
* ``attributes``: every per-vertex value of the file other than the coordinates and normals
  (colours, alpha, confidence, intensity, labels, LAS dimensions, XYZ extra columns ...), in file
  order, per **original** vertex, in the file's own dtype. Written back unchanged.
* ``normals``: per-vertex normals as read (``None`` if the file has none). Writers get them
  recomputed from the smoothed geometry, or dropped.
* ``precision``: how the file stored coordinates (dtype; printf specs matching the input's digits
  for text formats), so outputs keep the input's precision and size.
* ``layout``: a format-specific object that lets the same format write the file back with its
  structure (PLY elements and property order, OBJ statements, LAS header, GPX tree, ...).
* ``notes``: what the reader repaired or ignored; ``comments``: header comments, written back.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from service.core.geometry import Geometry

__all__ = ["GeometryDocument", "Polyline", "Precision", "WeldMap"]


@dataclass(frozen=True, eq=False)
class Polyline:
    """An open or closed polyline through vertex indices.

    Parameters
    ----------
    indices : array_like of int, shape (k,)
        Vertex indices in order, ``k >= 2``. A closed polyline does not repeat its first index.
    closed : bool
        Whether the last vertex connects back to the first.
    """

    indices: NDArray[np.int64]
    closed: bool = False

    def __post_init__(self) -> None:
        idx = np.asarray(self.indices, dtype=np.int64).reshape(-1)
        object.__setattr__(self, "indices", idx)
        object.__setattr__(self, "closed", bool(self.closed))

    def __len__(self) -> int:
        return int(self.indices.size)

    def edges(self) -> NDArray[np.int64]:
        """Consecutive pairs, plus ``(last, first)`` when closed; shape ``(k - 1 or k, 2)``."""
        idx = self.indices
        if self.closed and idx.size >= 3:
            return np.column_stack([idx, np.roll(idx, -1)])
        return np.column_stack([idx[:-1], idx[1:]])


@dataclass(frozen=True, eq=False)
class WeldMap:
    """How a welded document maps back to the file it was read from.

    Parameters
    ----------
    index : ndarray of int, shape (n_original,)
        ``index[i]`` is the welded vertex of original vertex ``i``.
    faces, standalone_edges : ndarray of int or None
        Connectivity as read, in original vertex indexing.
    polylines : list of Polyline
        Polylines as read, in original vertex indexing.
    weights : ndarray of float or None
        Per-original-vertex weights as read.
    fixed : ndarray of int or None
        Fixed original vertex indices as read.
    """

    index: NDArray[np.int64]
    faces: NDArray[np.int64] | None = None
    standalone_edges: NDArray[np.int64] | None = None
    polylines: list[Polyline] = field(default_factory=list)
    weights: NDArray[np.float64] | None = None
    fixed: NDArray[np.int64] | None = None

    @property
    def n_original(self) -> int:
        """Number of vertices in the file."""
        return int(self.index.size)


@dataclass(frozen=True)
class Precision:
    """How a file stored its coordinates.

    Parameters
    ----------
    dtype : str
        ``"float32"`` or ``"float64"`` (numpy names): what ``precision="input"`` writes.
    text : tuple of str, optional
        Text formats: one printf spec per coordinate reproducing the input's digits (see
        :mod:`service.io._shared.numfmt`); ``None``: shortest round-trip form of ``dtype``.
    attribute_text : mapping of str to str
        Text formats: printf spec of each attribute column, likewise.
    """

    dtype: str = "float64"
    text: tuple[str, ...] | None = None
    attribute_text: Mapping[str, str] = field(default_factory=dict)


@dataclass(frozen=True, eq=False)
class GeometryDocument:
    """A geometry read from a file, with what is needed to write it back.

    Parameters
    ----------
    geometry : Geometry
        What the engine smooths (welded, if read with ``weld=True``).
    polylines : list of Polyline
        Polylines in geometry indexing; their edges are included in ``geometry.edges``.
    source_format : str
        The registry name of the format read.
    standalone_edges : ndarray of int, shape (k, 2), optional
        Edges belonging to no polyline, in geometry indexing.
    notes : list of str
        What the reader repaired or ignored, one sentence each.
    weld : WeldMap, optional
        Set when the vertices were welded.
    comments : list of str
        Header comments of the file, written back by the formats that hold comments.
    attributes : dict of str to ndarray
        Per original vertex, file order, file dtype (see the module docstring).
    normals : ndarray, shape (n_original, 3), optional
        Normals as read.
    precision : Precision
        How the coordinates were stored.
    layout : object, optional
        Format-specific structure for writing the file back in its own format.
    """

    geometry: Geometry
    polylines: list[Polyline] = field(default_factory=list)
    source_format: str = "json"
    standalone_edges: NDArray[np.int64] | None = None
    notes: list[str] = field(default_factory=list)
    weld: WeldMap | None = None
    comments: list[str] = field(default_factory=list)
    attributes: dict[str, NDArray[Any]] = field(default_factory=dict)
    normals: NDArray[np.floating[Any]] | None = None
    precision: Precision = field(default_factory=Precision)
    layout: object | None = None

    @classmethod
    def from_geometry(cls, geometry: Geometry, source_format: str = "json") -> GeometryDocument:
        """Wrap a bare geometry: all its edges become standalone edges, no polylines."""
        return cls(geometry=geometry, source_format=source_format, standalone_edges=geometry.edges)

    @property
    def n_output(self) -> int:
        """Number of vertices a writer writes (the file's count, also when welded)."""
        return self.weld.n_original if self.weld is not None else self.geometry.n

    def with_points(self, points: ArrayLike) -> GeometryDocument:
        """The same document with new (e.g. smoothed) points, same count and order.

        Raises
        ------
        ValueError
            If ``points`` does not have the shape of ``geometry.points``.
        """
        pts = self.checked_points(points)
        g = self.geometry
        new = Geometry(pts, faces=g.faces, edges=g.edges, weights=g.weights, fixed=g.fixed)
        return replace(self, geometry=new)

    def with_extras(self, **changes: Any) -> GeometryDocument:
        """A copy with some fields replaced (readers add attributes, layout, ... this way)."""
        return replace(self, **changes)

    def checked_points(self, points: ArrayLike | None) -> NDArray[np.float64]:
        """``points`` as float64 with the shape of ``geometry.points`` (default: the geometry's).

        Raises
        ------
        ValueError
            On a shape mismatch.
        """
        if points is None:
            return self.geometry.points
        pts = np.asarray(points, dtype=np.float64)
        if pts.shape != self.geometry.points.shape:
            raise ValueError(
                f"points must have the shape of the document's points {self.geometry.points.shape},"
                f" got {pts.shape}"
            )
        return pts
