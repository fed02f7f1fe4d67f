"""Input geometry: points with optional faces, edges, per-point weights and fixed points.

A :class:`Geometry` is what the report calls the graph ``G = (V, E)`` of section 2.1 together
with the diagonal weight matrix ``D`` of eq. (3). It is validated on construction; only input that
has no meaning is rejected (non-finite coordinates, out-of-range indices, elements repeating a
vertex). Messy but meaningful input (duplicate or zero-area faces, unreferenced vertices,
non-manifold edges, several components) is accepted and handled by the engine.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from service.core.errors import (
    DegenerateElement,
    IndexOutOfRange,
    InvalidShape,
    NonFiniteCoordinates,
)

__all__ = ["Geometry", "GeometryKind", "mean_spacing"]

GeometryKind = Literal["mesh", "curve", "cloud"]


def _first(mask: object) -> list[int]:
    return [int(i) for i in np.flatnonzero(np.asarray(mask))[:10]]


def _index_array(values: ArrayLike, width: int, field: str, n: int) -> NDArray[np.int64]:
    arr = np.asarray(values)
    if arr.size == 0:
        return np.zeros((0, width), dtype=np.int64)
    if arr.ndim != 2 or arr.shape[1] != width:
        raise InvalidShape(
            f"{field.split('.')[-1]} must have shape (k, {width}), got {arr.shape}", field=field
        )
    if arr.dtype.kind == "f":
        if not np.all(np.isfinite(arr)) or np.any(arr != np.round(arr)):
            bad = ~np.isfinite(arr).all(axis=1) | (arr != np.round(arr)).any(axis=1)
            name = field.split(".")[-1]
            raise InvalidShape(
                f"{name} must hold integer indices", field=field, indices=_first(bad)
            )
    elif arr.dtype.kind not in "iu":
        raise InvalidShape(f"{field.split('.')[-1]} must hold integer indices", field=field)
    arr = arr.astype(np.int64)
    out = (arr < 0) | (arr >= n)
    if out.any():
        rows = out.any(axis=1)
        first = int(np.flatnonzero(rows)[0])
        raise IndexOutOfRange(
            f"{field.split('.')[-1]} {first} refers to vertex {int(arr[first][out[first]][0])},"
            f" outside [0, {n})",
            field=field,
            indices=_first(rows),
        )
    srt = np.sort(arr, axis=1)
    rep = (srt[:, 1:] == srt[:, :-1]).any(axis=1)
    if rep.any():
        first = int(np.flatnonzero(rep)[0])
        raise DegenerateElement(
            f"{field.split('.')[-1]} {first} repeats a vertex: {arr[first].tolist()}",
            field=field,
            indices=_first(rep),
        )
    return arr


@dataclass(frozen=True, eq=False)
class Geometry:
    """Points with optional connectivity, weights and fixed points.

    Parameters
    ----------
    points : array_like, shape (n, s)
        Input points ``P`` (report section 2.1), any dimension ``s >= 1``; converted to float64.
    faces : array_like, shape (m, 3), optional
        Triangles (mesh). Duplicate and zero-area faces are allowed.
    edges : array_like, shape (k, 2), optional
        Undirected edges: open or closed polylines and curve networks. With ``faces`` too, the
        edges give neighbours to vertices that no face references (mixed input).
    weights : array_like, shape (n,), optional
        The diagonal of ``D`` in eq. (3): positive per-point weights ``omega_i``; ``+inf`` marks
        a fixed point (report section 8). Default: all ones.
    fixed : array_like of int, optional
        Indices of fixed points, kept bit-identical (infinite weights, report section 8).

    Raises
    ------
    InvalidShape, NonFiniteCoordinates, IndexOutOfRange, DegenerateElement
        For input that has no meaning; the error names the field and the first indices.
    """

    points: NDArray[np.float64]
    faces: NDArray[np.int64] | None = None
    edges: NDArray[np.int64] | None = None
    weights: NDArray[np.float64] | None = None
    fixed: NDArray[np.int64] | None = None

    def __post_init__(self) -> None:
        pts = np.asarray(self.points)
        if pts.dtype.kind not in "fiu" or pts.ndim != 2:
            raise InvalidShape(
                f"points must be a numeric array of shape (n, s), got shape {pts.shape}",
                field="geometry.points",
            )
        n, s = pts.shape
        if n < 1 or s < 1:
            raise InvalidShape(
                f"points must have n >= 1 rows and s >= 1 columns, got {pts.shape}",
                field="geometry.points",
            )
        pts = np.ascontiguousarray(pts, dtype=np.float64)
        bad = ~np.isfinite(pts).all(axis=1)
        if bad.any():
            first = int(np.flatnonzero(bad)[0])
            raise NonFiniteCoordinates(
                f"point {first} has a non-finite coordinate: {pts[first].tolist()}",
                field="geometry.points",
                indices=_first(bad),
            )
        object.__setattr__(self, "points", pts)
        for name, width in (("faces", 3), ("edges", 2)):
            val = getattr(self, name)
            if val is not None:
                arr = _index_array(val, width, f"geometry.{name}", n)
                object.__setattr__(self, name, arr if len(arr) else None)
        if self.weights is not None:
            w = np.asarray(self.weights, dtype=np.float64).reshape(-1)
            if w.shape != (n,):
                raise InvalidShape(
                    f"weights must have one value per point ({n}), got {w.size}",
                    field="geometry.weights",
                )
            bad = np.isnan(w) | (w <= 0)
            if bad.any():
                raise NonFiniteCoordinates(
                    f"weights must be positive (or +inf for a fixed point); weight"
                    f" {int(np.flatnonzero(bad)[0])} is {w[bad][0]}",
                    field="geometry.weights",
                    indices=_first(bad),
                )
            object.__setattr__(self, "weights", w)
        if self.fixed is not None:
            f = np.asarray(self.fixed).reshape(-1)
            if (
                f.size
                and f.dtype.kind not in "iu"
                and (f.dtype.kind != "f" or np.any(f != np.round(f)))
            ):
                raise InvalidShape("fixed must hold integer indices", field="geometry.fixed")
            f = f.astype(np.int64)
            out = (f < 0) | (f >= n)
            if out.any():
                raise IndexOutOfRange(
                    f"fixed index {int(f[out][0])} is outside [0, {n})",
                    field="geometry.fixed",
                    indices=_first(out),
                )
            object.__setattr__(self, "fixed", np.unique(f))

    @property
    def n(self) -> int:
        """Number of points."""
        return int(self.points.shape[0])

    @property
    def dim(self) -> int:
        """Dimension ``s`` of the points."""
        return int(self.points.shape[1])

    @property
    def kind(self) -> GeometryKind:
        """``"mesh"`` with faces, ``"curve"`` with edges only, ``"cloud"`` otherwise."""
        if self.faces is not None:
            return "mesh"
        if self.edges is not None:
            return "curve"
        return "cloud"

    def omega(self) -> NDArray[np.float64]:
        """Finite per-point weights ``omega_i`` (ones where none were given or where fixed)."""
        if self.weights is None:
            return np.ones(self.n)
        w = self.weights.copy()
        w[~np.isfinite(w)] = 1.0
        return w

    def fixed_mask(self) -> NDArray[np.bool_]:
        """Points with infinite weight: listed in ``fixed`` or given weight ``+inf``."""
        mask = np.zeros(self.n, dtype=bool)
        if self.fixed is not None:
            mask[self.fixed] = True
        if self.weights is not None:
            mask |= np.isinf(self.weights)
        return mask


def mean_spacing(geometry: Geometry) -> float:
    """Mean edge length (meshes, curves) or mean nearest-neighbour distance (point clouds)."""
    P = geometry.points
    if geometry.faces is not None:
        F = geometry.faces
        e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    elif geometry.edges is not None:
        e = geometry.edges
    else:
        if geometry.n < 2:
            return 0.0
        return float(np.mean(_nearest_other(P)))
    return float(np.mean(np.linalg.norm(P[e[:, 0]] - P[e[:, 1]], axis=1)))


def _nearest_other(P: NDArray[np.float64]) -> NDArray[np.float64]:
    """Each point's distance to its nearest other point (``cKDTree.query(P, 2)``); copies of a
    point (0) found by one sort first, so that thousands of them do not make the k-d tree's
    search quadratic (issue 42 item 5: 80K copies of one point took 12.6 s)."""
    from scipy.spatial import cKDTree  # here: importing a Geometry stays scipy-free

    order = np.lexsort(P.T[::-1])
    S = P[order]
    first = np.r_[True, np.any(S[1:] != S[:-1], axis=1)]
    if first.all():
        return np.asarray(cKDTree(P).query(P, k=2)[0])[:, 1]
    group = np.cumsum(first) - 1
    U = S[first]
    du = np.asarray(cKDTree(U).query(U, k=2)[0])[:, 1] if U.shape[0] > 1 else np.zeros(1)
    d = np.empty(P.shape[0])
    d[order] = np.where(np.bincount(group)[group] > 1, 0.0, du[group])
    return d
