"""End conditions of ``L``: open-polyline endpoints and open-mesh boundaries (issue 21).

The report's eq. (1) gives every point the row ``x_i - sum_j w_ij x_j`` over its neighbours. At
the end of an open polyline that row is ``x_0 - x_1`` (one neighbour), and at a mesh boundary
vertex it averages a one-sided 1-ring; both pull the point *inwards along the shape*, so at any
lambda an open curve contracts along itself and an open surface shrinks at its border. The
distance to the true shape barely changes, but every sample slides: on open test curves the
vertex error at the best lambda was 1.3 - 2.7 times VTK's windowed-sinc, whose filter keeps
polyline endpoints in place and smooths boundary vertices along the boundary only.

* ``ends`` (polylines and curve networks): ``"fixed"`` keeps every degree-1 vertex in place
  (it is eliminated like a fixed point, report section 8; the curve between is smoothed up to
  it), ``"pulled"`` keeps the report's row.
* ``boundary`` (meshes): ``"curve"`` replaces a boundary vertex's row by the row of the
  boundary polyline through it (its neighbours along boundary edges, the edges of one face),
  ``"ring"`` keeps the report's one-sided 1-ring row. ``"curve"`` is what free displacement
  needs; with normal displacement only the normal part of a row counts, and there the boundary
  curve's own curvature (e.g. a hemisphere's rim) would be smoothed away, so ``"auto"`` picks
  ``"ring"`` for it (measurements: ``service/core/README.md``, issue 21).
"""

from __future__ import annotations

from typing import Literal

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from service.core._arrays import unique_keys
from service.core.geometry import Geometry
from service.core.operator.neighborhoods import Neighborhoods, pair_adjacency
from service.core.params import SmoothingParams
from service.core.params.rules import boundary_mode, displacement_mode

__all__ = [
    "boundary_edges",
    "boundary_rule",
    "ends_rule",
    "pinned_ends",
    "with_boundary_curve_rows",
]

BoundaryRule = Literal["ring", "curve"]
EndsRule = Literal["pulled", "fixed"]


def ends_rule(params: SmoothingParams) -> EndsRule:
    """``params.ends`` with ``"auto"`` resolved (``"fixed"``, as VTK's polyline smoothing)."""
    return "fixed" if params.ends == "auto" else params.ends


def boundary_rule(params: SmoothingParams, geometry: Geometry) -> BoundaryRule:
    """``params.boundary`` with ``"auto"`` resolved for the run's displacement: ``"curve"`` where
    the points move freely, ``"ring"`` with normal displacement (one rule,
    :func:`service.core.params.rules.boundary_mode`, for the displacement
    :func:`~service.core.params.rules.displacement_mode` resolves)."""
    if geometry.faces is None:
        return "ring"  # no mesh boundary: the rule does not apply
    mode = displacement_mode(
        params.displacement, geometry.kind, geometry.dim, params.method, params.tau_rule
    )
    return "curve" if boundary_mode(params.boundary, mode) == "curve" else "ring"


def pinned_ends(nb: Neighborhoods, rule: EndsRule) -> NDArray[np.bool_]:
    """Points the end rule keeps in place: open-polyline endpoints under ``"fixed"``."""
    if rule != "fixed" or nb.source != "curve":
        return np.zeros(nb.n, dtype=bool)
    return np.asarray(nb.boundary, dtype=bool).copy()


def boundary_edges(faces: NDArray[np.int64], n: int) -> NDArray[np.int64]:
    """Edges ``(a, b)``, ``a < b``, used by exactly one of the (distinct) triangles."""
    if len(faces) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e = np.sort(e, axis=1).astype(np.int64)
    keys, _, counts, _ = unique_keys(e[:, 0] * np.int64(n) + e[:, 1])
    once = keys[counts == 1]
    return np.column_stack([once // n, once % n])


def with_boundary_curve_rows(
    W: sp.csr_matrix, points: NDArray[np.float64], edges: NDArray[np.int64], uniform: bool
) -> sp.csr_matrix:
    """``W`` with the rows of boundary vertices replaced by their boundary-polyline rows.

    Parameters
    ----------
    W : scipy.sparse.csr_matrix, shape (n, n)
        Row-stochastic weights of the whole mesh.
    points : ndarray, shape (n, s)
    edges : ndarray, shape (b, 2)
        Boundary edges (:func:`boundary_edges`).
    uniform : bool
        Uniform weights along the boundary; else reciprocal edge lengths (section 4.2).

    Returns
    -------
    scipy.sparse.csr_matrix
        Row-stochastic; interior rows unchanged.
    """
    n = W.shape[0]
    if len(edges) == 0:
        return W
    i = np.concatenate([edges[:, 0], edges[:, 1]])
    j = np.concatenate([edges[:, 1], edges[:, 0]])
    B = pair_adjacency(i, j, n)
    if not uniform:
        coo = B.tocoo()
        length = np.linalg.norm(points[coo.row] - points[coo.col], axis=1)
        floor = max(float(np.ptp(points, axis=0).max()), 1.0) * 1e-12
        B = sp.csr_matrix((1.0 / np.maximum(length, floor), (coo.row, coo.col)), shape=(n, n))
    sums = np.asarray(B.sum(axis=1)).ravel()
    on = sums > 0
    inv = np.divide(1.0, sums, out=np.zeros_like(sums), where=on)
    out = sp.diags((~on).astype(float)) @ W + sp.diags(inv) @ B
    out = sp.csr_matrix(out)
    out.eliminate_zeros()
    return out
