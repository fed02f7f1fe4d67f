"""Normal-only displacement: ``x_i = p_i + N_i t_i`` with ``t_i`` in the normal space of ``p_i``.

Laplacian smoothing moves points along the shape as well as across it; against the clean
positions that tangential drift is error, and it is what the report's mean-value weights
computed on a noisy input produce (issue 9). Restricting every point to its normal line
(surfaces, point clouds of surfaces, curves in 2-D: one unknown per point) or normal plane
(curves in 3-D: two unknowns) removes it. With ``N_i`` an orthonormal basis of the normal space
(``s x r``), the mode ``displacement="normal"`` solves

    min_t  sum_i ||N_i^T (L (P + N t))_i||^2  +  lambda sum_i omega_i^2 ||t_i||^2,

eq. (4) with the smoothness measured across the shape (:func:`projected_normal_system`). The
component of ``L X`` along the shape is the sampling's irregularity, which moves along the normals
cannot undo; keeping it (``sum_c ||L (P + N t)^(c)||^2``, :func:`normal_system`) makes the normal
offsets compensate for it and measured worse on the quality benchmark (sphere with isotropic noise
0.5 h: distance to the surface 0.26 against 0.15 of the input's). Both are least-squares problems
of the form ``min ||A U - g||^2 + lambda ||D (U - U0)||^2`` with one row of ``U`` per unknown,
``U0 = 0`` and ``D`` repeating ``omega_i`` for the ``r`` unknowns of point ``i``. Because the
``N_i`` are orthonormal, ``||D (U - U0)||^2 = sum_i omega_i^2 ||x_i - p_i||^2``: phi and the tau
contract are exactly those of the free problem. Fixed points keep ``t_i = 0`` (eliminated like in
section 8).

Normals come from the input's neighbourhoods: principal directions of the ``k`` nearest
neighbours of each point after :data:`FRAME_STEPS` explicit averaging steps over the neighbourhood
graph (``x <- (x + mean of neighbours) / 2``), which take the noise out of the directions without
a factorization.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from service.core.errors import ParameterError
from service.core.geometry import Geometry
from service.core.linalg.cache import digest, frames
from service.core.linalg.gram import Gram
from service.core.noise.estimate import codimension
from service.core.operator.laplacian import presmooth
from service.core.operator.neighborhoods import Neighborhoods
from service.core.params import SmoothingParams
from service.core.params.rules import DEFAULT_DISPLACEMENT, displacement_mode
from service.core.system.deviation import SmoothingSystem

__all__ = [
    "DEFAULT_DISPLACEMENT",
    "NormalSystem",
    "auto_system",
    "normal_frames",
    "normal_mode",
    "normal_system",
    "projected_normal_system",
    "resolve_displacement",
    "tangential_ratio",
]

FRAME_NEIGHBOURS = 12
#: Bound on the estimated entries of the normal system, ``n min(n, 40) r^2``: above it an
#: explicit ``displacement="normal"`` is a ParameterError (``5e7`` entries: ~1.2 GB of COO).
NORMAL_MAX_ENTRIES = 50_000_000
#: Averaging steps before the normals are estimated (sphere with noise 0.5 h: 0 steps give
#: normals 19 degrees off, 3 steps 6.5, 10 steps 2.3; 10 steps round the creases of
#: fandisk.obj, 3-5 do not; see benchmarks/quality/README.md).
FRAME_STEPS = 5
#: Unknowns from which the normal system keeps ``M = A^T A`` as ``A``
#: (:class:`~service.core.linalg.gram.Gram`): the one-run Lanczos path of issue 30 needs only
#: products (``2 nnz(A)``, 14M at 1M vertices, against ``nnz(A^T A)`` = 19M), and forming
#: ``A^T A`` cost 1.7 s at 1M; a factorization forms it on demand.
GRAM_FROM = 20_000
#: Points from which the frames of surfaces in 3-D are computed in closed form on the grid
#: k-NN (:mod:`.fast_frames`; ``service.core.noise.fast_weights.COMPILED_FROM``).
COMPILED_FRAMES_FROM = 50_000


def normal_frames(
    points: NDArray[np.float64],
    adjacency: sp.csr_matrix,
    codim: int,
    k: int = FRAME_NEIGHBOURS,
    steps: int = FRAME_STEPS,
    at: NDArray[np.int64] | None = None,
) -> NDArray[np.float64]:
    """Orthonormal bases of the normal spaces, shape ``(n, s, codim)``.

    Parameters
    ----------
    points : ndarray, shape (n, s)
        Input points.
    adjacency : scipy.sparse.csr_matrix, shape (n, n)
        The neighbourhood graph (for the averaging steps).
    codim : int
        Normal dimensions ``r``: 1 for surfaces in 3-D and curves in 2-D, ``s - 1`` for curves.
    k : int
        Neighbours of the principal component analysis.
    steps : int
        Averaging steps before the analysis.
    at : ndarray of int, optional
        Only these points' frames (default: all).

    Returns
    -------
    ndarray, shape (n or len(at), s, codim)
        The ``codim`` directions of least variance of each neighbourhood. The last result is
        kept (the tangential step asks again for the frames the normal system used).
    """
    key = digest(points, adjacency.indptr, adjacency.indices, codim, k, steps, at)
    return frames.get_or_make(
        key, lambda: _frames(points, adjacency, codim, k, steps, at), copy=np.copy
    )


def _frames(
    points: NDArray[np.float64],
    adjacency: sp.csr_matrix,
    codim: int,
    k: int,
    steps: int,
    at: NDArray[np.int64] | None,
) -> NDArray[np.float64]:
    X = presmooth(points, adjacency, steps)
    n = X.shape[0]
    k = min(k, n)
    m = n if at is None else len(at)
    if codim == 1 and at is None and X.shape[1] == 3 and n >= COMPILED_FRAMES_FROM:
        from service.core.system.fast_frames import surface_normals  # issue 30: closed form

        return surface_normals(X, k)
    from service.core.operator.knn import tree_knn  # coincident points collapsed (issue 42)
    from service.core.operator.sized_kernels import neighbourhood_covariances

    _, idx = tree_knn(X, k, np.arange(n) if at is None else np.asarray(at, dtype=np.int64))
    idx = np.ascontiguousarray(idx, dtype=np.int64)
    out = np.empty((m, X.shape[1], codim))
    for start in range(0, m, 250000):
        cov = neighbourhood_covariances(X, idx[start : start + 250000])
        out[start : start + 250000] = np.linalg.eigh(cov)[1][:, :, :codim]  # ascending variance
    return out


@dataclass(frozen=True)
class NormalSystem:
    """The normal equations of normal-only displacement (see the module docstring).

    Attributes
    ----------
    M : scipy.sparse.csc_matrix or Gram, shape (m r, m r)
        ``A^T A`` (kept as ``A`` from :data:`GRAM_FROM` unknowns).
    d2 : ndarray, shape (m r,)
        ``omega_i^2`` repeated for the ``r`` unknowns of each free point.
    b : ndarray, shape (m r, 1)
        ``A^T g``.
    U0 : ndarray, shape (m r, 1)
        Zeros: no displacement.
    frames : ndarray, shape (m, s, r)
        Normal bases of the free points.
    """

    M: sp.csc_matrix | Gram
    d2: NDArray[np.float64]
    b: NDArray[np.float64]
    U0: NDArray[np.float64]
    frames: NDArray[np.float64]

    def points(self, P_free: NDArray[np.float64], U: NDArray[np.float64]) -> NDArray[np.float64]:
        """Free points ``p_i + N_i t_i`` for the solution ``U`` (shape (m r, 1))."""
        m, _, r = self.frames.shape
        return P_free + np.einsum("nsr,nr->ns", self.frames, U.reshape(m, r))


def _blocks(
    S: sp.coo_matrix, frames: NDArray[np.float64], r: int
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
    """COO entries of the block matrix whose block ``(i, j)`` is ``S_ij N_i^T N_j``."""
    G = np.einsum("ksa,ksb->kab", frames[S.row], frames[S.col])
    a, bb = np.meshgrid(np.arange(r), np.arange(r), indexing="ij")
    rows = (S.row[:, None, None] * r + a[None]).ravel()
    cols = (S.col[:, None, None] * r + bb[None]).ravel()
    return rows, cols, np.repeat(S.data, r * r) * G.reshape(-1)


def projected_normal_system(
    L_F: sp.spmatrix,
    LP: NDArray[np.float64],
    frames: NDArray[np.float64],
    w2: NDArray[np.float64],
) -> NormalSystem:
    """Normal-only displacement with the smoothness measured across the shape only.

    ``min_t sum_i ||N_i^T (L (P + N t))_i||^2 + lambda sum_i omega_i^2 ||t_i||^2``: the
    component of the Laplacian along the shape is the sampling's irregularity (and tangential
    noise), which displacements along the normals cannot and should not undo; counting it
    (:func:`normal_system`) makes the normal offsets compensate for it. ``A`` has blocks
    ``L_ij N_i^T N_j`` and ``g_i = -N_i^T (L P)_i``; rows of ``L_F`` are those of the free
    points, in the order of ``frames``. Same arguments and result as :func:`normal_system`.
    """
    m, _, r = frames.shape
    if r == 1:  # A has the pattern of L_F, entries L_ij (n_i . n_j): scale its data in place
        A = sp.csr_matrix(L_F, copy=True)
        A.sum_duplicates()
        f = frames[:, :, 0]
        if m >= COMPILED_FRAMES_FROM and f.shape[1] == 3:
            from service.core.system.fast_frames import scale_by_normals

            scale_by_normals(A.indptr, A.indices, A.data, np.ascontiguousarray(f))
        else:
            rows = np.repeat(np.arange(m), np.diff(A.indptr))
            A.data *= np.einsum("ks,ks->k", f[rows], f[A.indices])
    else:
        rows, cols, vals = _blocks(sp.coo_matrix(L_F), frames, r)
        A = sp.csr_matrix((vals, (rows, cols)), shape=(m * r, m * r))
    g = -np.einsum("nsa,ns->na", frames, np.asarray(LP)).reshape(m * r)
    b = np.asarray(A.T @ g).reshape(m * r, 1)
    if m * r >= GRAM_FROM:  # issue 30: products by A and A^T; formed only if factorized
        return NormalSystem(Gram(A), np.repeat(w2, r), b, np.zeros((m * r, 1)), frames)
    M = (A.T @ A).tocsc()
    M.eliminate_zeros()
    return NormalSystem(M, np.repeat(w2, r), b, np.zeros((m * r, 1)), frames)


def normal_system(
    L_F: sp.spmatrix,
    LP: NDArray[np.float64],
    frames: NDArray[np.float64],
    w2: NDArray[np.float64],
) -> NormalSystem:
    """Assemble ``M = A^T A``, ``b = A^T g`` of normal-only displacement (full Laplacian).

    Parameters
    ----------
    L_F : scipy.sparse matrix, shape (q, m)
        Rows of ``L`` that take part (those of the free points), free columns.
    LP : ndarray, shape (q, s)
        ``L P`` on the same rows (fixed points' contributions included).
    frames : ndarray, shape (m, s, r)
        Orthonormal normal bases of the free points.
    w2 : ndarray, shape (m,)
        ``omega_i^2`` of the free points.

    Returns
    -------
    NormalSystem
    """
    m, _, r = frames.shape
    # block (i, j) of M is (L^T L)_ij N_i^T N_j (r x r)
    rows, cols, vals = _blocks(sp.csr_matrix(L_F.T @ L_F).tocoo(), frames, r)
    M = sp.csc_matrix((vals, (rows, cols)), shape=(m * r,) * 2)
    M.sum_duplicates()
    M.eliminate_zeros()
    LtLP = np.asarray(L_F.T @ LP)  # (m, s)
    b = -np.einsum("nsa,ns->na", frames, LtLP).reshape(m * r, 1)
    return NormalSystem(M, np.repeat(w2, r), b, np.zeros((m * r, 1)), frames)


def normal_mode(
    geometry: Geometry,
    L: sp.csr_matrix,
    nb: Neighborhoods,
    P: NDArray[np.float64],
    omega: NDArray[np.float64],
    fixed: NDArray[np.bool_],
) -> tuple[SmoothingSystem, Callable[[NDArray[np.float64]], NDArray[np.float64]]]:
    """The :class:`SmoothingSystem` of normal-only displacement for the free points, and the
    map from its solution to the free points (internal frame ``P``, weights ``omega``).

    Raises
    ------
    ParameterError
        When the points have no normal direction (a surface in 2-D, 1-D data).
    """
    codim = codimension(geometry)
    if codim < 1:
        raise ParameterError(
            f"displacement 'normal' needs a normal direction: a {geometry.kind} in "
            f"{geometry.dim}-D has none; use displacement 'free'",
            field="params.displacement",
        )
    if fixed.any():
        free = np.flatnonzero(~fixed)
        frames = normal_frames(P, nb.adjacency, codim)[free]
        L_R = sp.csr_matrix(L)[free]
        ns = projected_normal_system(L_R[:, free], np.asarray(L_R @ P), frames, omega[free] ** 2)
        P_F = P[free]
    else:  # the same system without the row and column selections (issue 30)
        L_R = sp.csr_matrix(L)
        frames = normal_frames(P, nb.adjacency, codim)
        ns = projected_normal_system(L_R, np.asarray(L_R @ P), frames, omega**2)
        P_F = P
    return SmoothingSystem(ns.M, ns.d2, ns.b, ns.U0), lambda U: ns.points(P_F, U)


def tangential_ratio(points: NDArray[np.float64], adjacency: sp.csr_matrix, codim: int) -> float:
    """``rho = sum ||T_i (L_u P)_i||^2 / sum ||N_i^T (L_u P)_i||^2`` of the uniform Laplacian.

    How much of the roughness of the input lies along the shape rather than across it: near 0
    for noise along the normals on a regular sampling, about 2 for isotropic noise on a
    surface (two tangent directions against one normal direction). The automatic tau of free
    displacement spends budget on it (:func:`service.core.search.autotau.discrepancy_tau`).
    """
    deg = np.asarray(adjacency.sum(axis=1)).ravel()
    inv = np.divide(1.0, deg, out=np.zeros_like(deg), where=deg > 0)
    n = points.shape[0]
    at = np.arange(n) if n <= 20000 else np.random.default_rng(0).choice(n, 20000, replace=False)
    LP = (points - np.asarray((sp.diags(inv) @ adjacency) @ points))[at]
    LP[deg[at] == 0] = 0.0
    N = normal_frames(points, adjacency, codim, at=at)
    across = float(np.sum(np.einsum("nsa,ns->na", N, LP) ** 2))
    total = float(np.sum(LP**2))
    return (total - across) / across if across > 0 else 0.0


def resolve_displacement(params: SmoothingParams, geometry: Geometry) -> SmoothingParams:
    """``params`` with ``displacement="auto"`` replaced by the mode for this kind of input:
    free for ``method="windowed-sinc"`` (Taubin's filter of the points themselves) and for
    ``tau="gcv"`` (cross-validation assumes the data are the points: in normal displacement the
    Laplacian of the clean curved shape is part of the data and its score falls towards the
    collapsed shape). Normal displacement only up to codimension
    :data:`~service.core.params.rules.AUTO_NORMAL_MAX_CODIM` (its cost grows like
    ``r^2``-``r^3``): :func:`~service.core.params.rules.displacement_mode`, the one rule.

    Raises
    ------
    ParameterError
        ``tau="gcv"`` with ``displacement="normal"``; ``displacement="normal"`` whose system
        would exceed :data:`NORMAL_MAX_ENTRIES`.
    """
    if params.displacement == "normal" and params.tau_rule == "gcv":
        raise ParameterError(
            "tau 'gcv' needs displacement 'free' (or 'auto')", field="params.displacement"
        )
    r = codimension(geometry)
    entries = geometry.n * min(geometry.n, 40) * r * r
    if params.displacement == "normal" and entries > NORMAL_MAX_ENTRIES:
        raise ParameterError(
            f"displacement 'normal' in {geometry.dim}-D has {r} normal directions per point: "
            f"its system would hold about {entries:.3g} entries (bound {NORMAL_MAX_ENTRIES:.3g});"
            " use displacement 'free' or 'auto'",
            field="params.displacement",
        )
    if params.displacement == "normal" and "tangential" not in params.model_fields_set:
        return params.model_copy(update={"tangential": "off"})
    kind, dim = geometry.kind, geometry.dim
    mode = displacement_mode(params.displacement, kind, dim, params.method, params.tau_rule)
    if mode == params.displacement:
        return params
    return params.model_copy(update={"displacement": mode})


ToPoints = Callable[[NDArray[np.float64]], NDArray[np.float64]]


def auto_system(
    params: SmoothingParams,
    requested: str,
    build: Callable[[SmoothingParams], tuple[SmoothingSystem, ToPoints]],
) -> tuple[SmoothingParams, SmoothingSystem, ToPoints]:
    """``build(params)``, or the free system when ``displacement="auto"`` chose normal
    displacement for an input that is already smooth across itself (a flat cloud or mesh:
    nothing moves along the normals, every budget would be out of range)."""
    system, to_points = build(params)
    if requested == "auto" and params.displacement == "normal" and not np.any(system.r):
        params = params.model_copy(update={"displacement": "free"})
        system, to_points = build(params)
    return params, system, to_points
