"""What a reader returns and a writer needs: :class:`GeometryDocument` and :class:`Polyline`.

A document wraps the validated :class:`~service.core.geometry.Geometry` the engine smooths, plus
what is needed to write the result back in the input's shape:

* ``polylines``: OBJ ``l`` elements and JSON ``polylines``, in geometry indexing. Their edges
  (consecutive pairs, plus the closing pair of a closed polyline) are part of ``geometry.edges``.
* ``standalone_edges``: edges that belong to no polyline (PLY ``edge`` elements, JSON ``edges``).
  ``geometry.edges`` is these followed by the polyline edges.
* ``weld``: set when the file was read with ``weld=True``. The geometry then holds one vertex per
  distinct position, and :attr:`WeldMap.index` maps every vertex of the file to its welded vertex.
  Writers use :meth:`GeometryDocument.output_points` and the ``output_*`` accessors, so the file
  written keeps the input's vertex count, order and connectivity: each original vertex gets the
  (smoothed) position of its welded vertex.
* ``notes``: what the reader repaired or ignored (dropped degenerate faces, skipped elements, ...).
* ``comments``: header comments of the file (PLY ``comment`` lines, OBJ/XYZ leading ``#`` lines),
  written back so attributions (e.g. CC BY notices) survive a round trip.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from service.core.geometry import Geometry

__all__ = ["GeometryDocument", "Polyline", "WeldMap"]


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
        Connectivity as read, in original vertex indexing (degenerate elements of the file
        already dropped; nothing dropped by welding).
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
        The format read (``"ply"``, ``"obj"``, ``"xyz"`` or ``"json"``).
    standalone_edges : ndarray of int, shape (k, 2), optional
        Edges belonging to no polyline, in geometry indexing.
    notes : list of str
        What the reader repaired or ignored, one sentence each.
    weld : WeldMap, optional
        Set when the vertices were welded; writers then restore the original vertex count.
    comments : list of str
        Header comments of the file, written back by the PLY, OBJ and XYZ writers.
    """

    geometry: Geometry
    polylines: list[Polyline] = field(default_factory=list)
    source_format: str = "json"
    standalone_edges: NDArray[np.int64] | None = None
    notes: list[str] = field(default_factory=list)
    weld: WeldMap | None = None
    comments: list[str] = field(default_factory=list)

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
        pts = self._checked_points(points)
        g = self.geometry
        new = Geometry(pts, faces=g.faces, edges=g.edges, weights=g.weights, fixed=g.fixed)
        return replace(self, geometry=new)

    def _checked_points(self, points: ArrayLike | None) -> NDArray[np.float64]:
        if points is None:
            return self.geometry.points
        pts = np.asarray(points, dtype=np.float64)
        if pts.shape != self.geometry.points.shape:
            raise ValueError(
                f"points must have the shape of the document's points {self.geometry.points.shape},"
                f" got {pts.shape}"
            )
        return pts

    def output_points(self, points: ArrayLike | None = None) -> NDArray[np.float64]:
        """Points to write: ``points`` (default: the geometry's), un-welded to the file's order."""
        pts = self._checked_points(points)
        if self.weld is not None:
            return pts[self.weld.index]
        return pts

    def output_faces(self) -> NDArray[np.int64] | None:
        """Triangles to write, in output vertex indexing."""
        return self.weld.faces if self.weld is not None else self.geometry.faces

    def output_standalone_edges(self) -> NDArray[np.int64] | None:
        """Edges that belong to no polyline, in output vertex indexing."""
        return self.weld.standalone_edges if self.weld is not None else self.standalone_edges

    def output_polylines(self) -> list[Polyline]:
        """Polylines to write, in output vertex indexing."""
        return self.weld.polylines if self.weld is not None else self.polylines

    def output_edges(self) -> NDArray[np.int64] | None:
        """All edges to write (standalone, then polyline edges), in output vertex indexing."""
        parts = [p.edges() for p in self.output_polylines()]
        standalone = self.output_standalone_edges()
        if standalone is not None:
            parts.insert(0, standalone)
        parts = [p for p in parts if len(p)]
        return np.concatenate(parts).astype(np.int64) if parts else None

    def output_weights(self) -> NDArray[np.float64] | None:
        """Per-vertex weights to write, in output vertex indexing."""
        return self.weld.weights if self.weld is not None else self.geometry.weights

    def output_fixed(self) -> NDArray[np.int64] | None:
        """Fixed vertex indices to write, in output vertex indexing."""
        return self.weld.fixed if self.weld is not None else self.geometry.fixed
