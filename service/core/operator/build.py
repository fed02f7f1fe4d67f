"""``build_operator()``: neighbourhoods, weights, curvature and the Laplacian (report section 4).

The operator is everything about an input that does not depend on tau: it can be built once
and smoothed at several tau (``smooth(geometry, params, operator=op)``), and it is cached per
geometry and build parameters in the process (:mod:`service.core.linalg.cache`).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from service.core.errors import ParameterError
from service.core.frame import Frame
from service.core.geometry import Geometry
from service.core.linalg import cache
from service.core.operator.boundary import (
    boundary_edges,
    boundary_rule,
    ends_rule,
    pinned_ends,
    with_boundary_curve_rows,
)
from service.core.operator.curvature import curvature
from service.core.operator.delaunay import cloud_delaunay_neighborhoods
from service.core.operator.laplacian import laplacian, presmooth, without_junction_rows
from service.core.operator.neighborhoods import (
    Neighborhoods,
    cloud_knn_neighborhoods,
    curve_neighborhoods,
    mesh_neighborhoods,
    unique_faces,
)
from service.core.operator.weights import ResolvedScheme, neighbor_weights
from service.core.params import OperatorParams, SmoothingParams
from service.core.params.groups import field_names

__all__ = [
    "BUILD_FIELDS",
    "SmoothingOperator",
    "build_laplacian",
    "build_operator",
    "operator_group",
    "operator_key",
    "resolve_weights",
]

#: The parameters an operator depends on: the fields of the operator group.
BUILD_FIELDS = field_names(OperatorParams)


@dataclass(frozen=True, eq=False)
class SmoothingOperator:
    """The Laplacian of one geometry, in the internal frame (:mod:`service.core.frame`).

    Attributes
    ----------
    L : scipy.sparse.csr_matrix, shape (n, n)
        ``L^(n)``, ``L^(kappa)`` or ``L^(f)`` of the internal points.
    neighborhoods : Neighborhoods
    scheme : str
        Resolved weight scheme.
    frame : Frame
    key : str
        Digest of the geometry and the build parameters it was built for.
    timings : dict
        Seconds for ``neighborhoods`` and ``laplacian``.
    pinned : ndarray of bool, shape (n,), optional
        Points the end rule keeps in place (open-polyline endpoints with ``ends="fixed"``,
        :mod:`.boundary`); eliminated like fixed points.
    """

    L: sp.csr_matrix
    neighborhoods: Neighborhoods
    scheme: ResolvedScheme
    frame: Frame
    key: str
    timings: dict[str, float] = field(default_factory=dict)
    pinned: NDArray[np.bool_] | None = None


def resolve_weights(params: SmoothingParams, geometry: Geometry) -> ResolvedScheme:
    """The weight scheme actually used: ``auto`` resolved as in the report.

    Reciprocal distance for curves (section 4.2) and k-NN neighbourhoods; mean value for meshes
    (4.3) and Delaunay neighbourhoods (4.4).

    Raises
    ------
    ParameterError
        For triangle-based weights without triangles (curves, k-NN neighbourhoods).
    """
    kind = geometry.kind
    triangles = kind == "mesh" or (kind == "cloud" and params.neighborhood == "delaunay")
    if params.weights == "auto":
        return "mean-value" if triangles else "reciprocal"
    if params.weights in ("mean-value", "cotangent") and not triangles:
        where = "a curve" if kind == "curve" else "k-NN neighbourhoods"
        raise ParameterError(
            f"weights '{params.weights}' need triangles, which {where} do not have: use "
            "'reciprocal' or 'uniform'"
            + (", or neighborhood 'delaunay'" if kind == "cloud" else ""),
            field="params.weights",
        )
    return params.weights


def _neighborhoods(geometry: Geometry, P: np.ndarray, params: SmoothingParams) -> Neighborhoods:
    if geometry.faces is not None:
        return mesh_neighborhoods(geometry.faces, geometry.n, geometry.edges)
    if geometry.edges is not None:
        return curve_neighborhoods(geometry.edges, geometry.n)
    if params.neighborhood == "delaunay":
        return cloud_delaunay_neighborhoods(P, params.k)
    return cloud_knn_neighborhoods(P, params.k)


def operator_group(params: SmoothingParams, geometry: Geometry) -> OperatorParams:
    """The operator group of ``params`` with its ``"auto"`` choices resolved (weights, ends,
    boundary): the same for the caller's parameters and for the plan's."""
    return dataclasses.replace(
        params.operator,
        weights=resolve_weights(params, geometry),
        ends=ends_rule(params),
        boundary=boundary_rule(params, geometry),
    )


def operator_key(geometry: Geometry, params: SmoothingParams) -> str:
    """Digest of what an operator depends on: points, connectivity and the resolved operator
    group (:func:`operator_group`)."""
    return cache.digest(
        geometry.points,
        geometry.faces if geometry.faces is not None else 0,
        geometry.edges if geometry.edges is not None else 0,
        *dataclasses.astuple(operator_group(params, geometry)),
    )


def build_operator(geometry: Geometry, params: SmoothingParams) -> SmoothingOperator:
    """Neighbourhoods, weights, curvature and the Laplacian variant (cached per input).

    Parameters
    ----------
    geometry : Geometry
    params : SmoothingParams
        Only :data:`BUILD_FIELDS` matter.

    Returns
    -------
    SmoothingOperator

    Raises
    ------
    ParameterError
        Triangle weights without triangles.
    """
    scheme = resolve_weights(params, geometry)
    key = operator_key(geometry, params)
    return cache.operators.get_or_make(key, lambda: _build(geometry, params, scheme, key))


def _build(
    geometry: Geometry, params: SmoothingParams, scheme: ResolvedScheme, key: str
) -> SmoothingOperator:
    frame = Frame.of(geometry.points, params.laplacian)
    P = frame.points(geometry.points)
    t0 = time.perf_counter()
    nb = _neighborhoods(geometry, P, params)
    curv_nb = nb
    if params.laplacian != "normalized" and nb.source == "knn":
        curv_nb = cloud_delaunay_neighborhoods(P, params.k)  # curvature from Delaunay fans
    t1 = time.perf_counter()
    W = neighbor_weights(P, nb, scheme)
    if nb.source == "mesh" and nb.boundary.any() and boundary_rule(params, geometry) == "curve":
        assert geometry.faces is not None
        edges = boundary_edges(unique_faces(geometry.faces), geometry.n)
        W = with_boundary_curve_rows(W, P, edges, uniform=scheme == "uniform")
    ref = P  # curvature and row scales of L(kappa)/L(f) from the pre-smoothed input (quality)
    if params.laplacian != "normalized" and params.presmooth:
        ref = presmooth(P, nb.adjacency, params.presmooth)
    kappa = curvature(ref, curv_nb) if params.laplacian != "normalized" else None
    L = laplacian(W, ref, params.laplacian, kappa, params.sigma_h / frame.scale, params.sigma_f)
    if nb.source == "curve" and params.junctions == "corner":
        L = without_junction_rows(L, nb.adjacency)
    t2 = time.perf_counter()
    timings = {"neighborhoods": t1 - t0, "laplacian": t2 - t1}
    pinned = pinned_ends(nb, ends_rule(params))
    nb = dataclasses.replace(nb, adjacency=_frozen(nb.adjacency))
    return SmoothingOperator(_frozen(L), nb, scheme, frame, key, timings, pinned)


def _frozen(A: sp.spmatrix) -> sp.csr_matrix:
    """``A`` in canonical CSR (rows' entries in column order, no duplicates), read-only: the
    cached operator is shared by later runs, and a run that canonicalized it in place (scipy
    sorts a matrix's indices when an operation needs them sorted) changed the order in which
    the next run's products summed each row, so its output bits (issue 38: a golden case failed
    after another run of the same input in the process)."""
    A = sp.csr_matrix(A)
    A.sum_duplicates()
    for part in (A.data, A.indices, A.indptr):
        part.flags.writeable = False
    return A


def build_laplacian(
    geometry: Geometry, params: SmoothingParams
) -> tuple[sp.csr_matrix, Neighborhoods, ResolvedScheme, dict[str, float]]:
    """The Laplacian of ``geometry`` in the input's frame (``L = s^-p L'``), for tests and tools.

    Returns
    -------
    L : scipy.sparse.csr_matrix, shape (n, n)
    nb : Neighborhoods
    scheme : str
    timings : dict
    """
    op = build_operator(geometry, params)
    L = op.L * op.frame.scale ** (-op.frame.power) if op.frame.power else op.L
    return sp.csr_matrix(L), op.neighborhoods, op.scheme, dict(op.timings)
