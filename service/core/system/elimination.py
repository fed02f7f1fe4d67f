"""The report's system with fixed points eliminated (section 8) and its ``phi(0)`` (eqs. 13-14).

Fixed points ``C`` have infinite weight: their rows of eq. (16) disappear and their columns move
to the right-hand side. For the free points ``F`` (internal frame, :mod:`service.core.frame`)::

    M = L_F^T L_F,   b = -L_F^T L_C P_C,   U0 = P_F,   d2 = omega_F^2.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.sparse.csgraph import connected_components

from service.core._arrays import unique_keys
from service.core.linalg.solver import Gram, split_fixed
from service.core.system.deviation import Deviation, SmoothingSystem

__all__ = ["laplacian_system", "phi_at_zero"]

Array = NDArray[np.float64]


def laplacian_system(
    L: sp.csr_matrix, P: Array, omega: Array, fixed: NDArray[np.bool_]
) -> SmoothingSystem:
    """Eq. (17) for the free points, with ``phi(0)`` in closed form when no point is fixed.

    Parameters
    ----------
    L : scipy.sparse.csr_matrix, shape (n, n)
    P : ndarray, shape (n, s)
        Internal-frame points.
    omega : ndarray, shape (n,)
        Internal-frame finite weights.
    fixed : ndarray of bool, shape (n,)
    """
    L_F, L_C, free, fixed_idx = split_fixed(L, fixed)
    b = np.zeros((free.size, P.shape[1]))
    if fixed_idx.size and free.size:
        b = -np.asarray(L_F.T @ (L_C @ P[fixed_idx]))
    M = Gram(L_F)
    labels, has_fixed = _components(L, fixed, free)
    d2 = omega[free] ** 2
    phi0 = bound = None
    if not has_fixed[labels[free]].any():
        E0 = _centroid_offsets(labels[free], d2, P[free])
        phi0 = float(np.sum(d2[:, None] * E0**2))
    elif free.size:
        bound = _phi0_bound(P[free], d2, P[fixed_idx])
    return SmoothingSystem(M, d2, b, P[free], phi0=phi0, phi0_bound=bound)


def _components(
    L: sp.csr_matrix, fixed: NDArray[np.bool_], free: NDArray[np.int64]
) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """Connected components of the coupling graph; which ones contain a fixed point."""
    n = L.shape[0]
    coo = L[free].tocoo()
    g = sp.csr_matrix((np.ones(coo.nnz), (free[coo.row], coo.col)), shape=(n, n))
    labels = connected_components(g, directed=False)[1]
    has_fixed = np.zeros(labels.max() + 1 if n else 0, dtype=bool)
    has_fixed[labels[fixed]] = True
    return labels, has_fixed


def _centroid_offsets(lab: NDArray[np.int64], w2: Array, U: Array) -> Array:
    """``P_bar - P`` per component: the limit ``lambda -> 0`` of the deviation (eq. 14)."""
    if lab.size == 0:
        return np.zeros_like(U)
    _, _, _, lab = unique_keys(lab)
    sw = np.bincount(lab, weights=w2)
    cen = np.stack([np.bincount(lab, weights=w2 * U[:, c]) for c in range(U.shape[1])], axis=1)
    return cen[lab] / np.maximum(sw, 1e-300)[lab, None] - U


def phi_at_zero(dev: Deviation, L: sp.csr_matrix, fixed: NDArray[np.bool_]) -> float:
    """``phi(0)`` of the Laplacian system of ``dev`` (eqs. 13-14).

    Closed form on components without fixed points; on the others ``M`` is definite and
    ``phi(0)`` is the deviation of that sub-system at the lambda floor (one factorization,
    added to ``dev.stats``).
    """
    s = dev.system
    if s.phi0 is not None:
        return s.phi0
    free = np.flatnonzero(~fixed)
    labels, has_fixed = _components(L, fixed, free)
    lab = labels[free]
    sub = has_fixed[lab]
    E0 = np.zeros_like(s.U0)
    E0[~sub] = _centroid_offsets(lab[~sub], s.d2[~sub], s.U0[~sub])
    idx = np.flatnonzero(sub)
    M = s.M.columns(idx) if isinstance(s.M, Gram) else s.M[idx][:, idx]
    part = SmoothingSystem(M, s.d2[idx], s.b[idx], s.U0[idx])
    name: Any = dev.solver.name
    sub_dev = Deviation(part, solver=name)
    E0[idx] = sub_dev.deviation(sub_dev.floor)
    for key in ("factorizations", "solves", "matvecs", "factorization", "solve", "analysis"):
        setattr(dev.stats, key, getattr(dev.stats, key) + getattr(sub_dev.stats, key))
    return float(np.sum(s.d2[:, None] * E0**2))


def _phi0_bound(U: Array, d2: Array, fixed_points: Array) -> float:
    """An upper bound of ``phi(0)`` without a solve.

    As lambda -> 0 the free points of a component with fixed points tend to the solution of
    ``L X = 0`` on the free rows: a discrete harmonic function of the fixed values, which the
    normalized Laplacian's convex combinations (and any positive row scaling of them, eqs. 9-10)
    keep inside the bounding box of the fixed points (maximum principle). So each coordinate
    moves at most to the farther side of that box. Components without fixed points contribute
    at most the same (their centroid lies in the box of all points, which this also bounds
    from above when the box is taken over fixed and free points).

    Parameters
    ----------
    U : ndarray, shape (m, s)
        Free points (internal frame).
    d2 : ndarray, shape (m,)
    fixed_points : ndarray, shape (c, s)
        Internal-frame coordinates of the fixed points.
    """
    lo = np.minimum(fixed_points.min(axis=0), U.min(axis=0))
    hi = np.maximum(fixed_points.max(axis=0), U.max(axis=0))
    far = np.maximum(np.abs(U - lo), np.abs(U - hi))
    return float(np.sum(d2[:, None] * far**2))
