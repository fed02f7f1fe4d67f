"""The residual test (issue 40): was what the solve removed noise, or shape?

The displacement the solve removed, ``R = P - X`` (before the tangential step, so along the
normals in normal mode), is noise wherever the default did its job: a high-pass of white noise,
whose neighbouring values are uncorrelated or anti-correlated. Where the solve removed shape (a
step rounded, a boundary pulled in, a crease cut) the removed field is coherent: neighbouring
points lost the same thing. Per point ``i``, over its ball ``B_i`` of :data:`HOPS` hops of the
operator's graph (the pulled outliers and fixed points left out),

    ``rho_i = sum_{j in B_i} R_j . (sum_{k ~ j} R_k) / sum_{j in B_i} deg_j |R_j|^2``

(``k ~ j``: graph neighbours) is the removed field's local lag-one correlation: about 0 or
below for removed noise, near 1 for removed shape. It uses neither the estimated sigma (which
reads 0.5 - 0.75 of the truth at 1 edge of noise and many times it on stairs) nor tau. Where
``rho_i`` exceeds :data:`RHO_BACKOFF` at a point and at :data:`CLUSTER` or more of its graph
neighbours the run backs off locally, as if the point's data weight
were raised: ``X_i + g_i R_i`` with ``g_i = min(1, 2 (rho_i - RHO_BACKOFF) / (1 -
RHO_BACKOFF))``; the report's warnings say at how many points and by how much.

Calibrated on the calibration half of ``benchmarks/quality/harm.py`` and of issue 21's
families (``service/core/README.md``, issue 40): on clean-noise cases (smooth shapes, uniform
noise) ``rho_i`` stays below 0.60, so 0.65 backs off nowhere there.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

__all__ = ["ALPHA", "CLUSTER", "HOPS", "RHO_BACKOFF", "BackOff", "back_off", "beyond_noise",
           "correlation"]

Array = NDArray[np.float64]
#: Hops over the operator's graph that make a point's neighbourhood (2: ~19 points on a mesh).
HOPS = 2
#: ``rho_i`` above which the removed displacement is shape, not noise (calibration: on
#: clean-noise cases ``rho_i`` has median 0 +- 0.05 and spread 0.09 - 0.12, its largest 0.60 on
#: 2.5K - 10K points; see ``service/core/README.md``, issue 40).
RHO_BACKOFF = 0.65
#: Graph neighbours that must be above it too: removed shape is a region, not a point.
CLUSTER = 2
#: Family-wise level of the noise's Gaussian extreme (:func:`beyond_noise`).
ALPHA = 0.01


@dataclass(frozen=True)
class BackOff:
    """Where the residual test backed off and by how much.

    Attributes
    ----------
    points : ndarray of int
        The points whose removed displacement was coherent (``rho_i > RHO_BACKOFF``).
    rho_max : float
        The largest ``rho_i``.
    restored_rms : float
        RMS over those points of the displacement put back.
    removed_rms : float
        RMS over those points of the displacement the solve had removed.
    n : int
        Points tested.
    put : ndarray, shape (len(points), s)
        The displacement put back at those points.
    """

    points: NDArray[np.int64]
    rho_max: float
    restored_rms: float
    removed_rms: float
    n: int
    put: Array

    def undone(self, X: Array) -> Array:
        """``X`` without the back-off: the moves the smoothing made (the outlier count compares
        a pulled point's move with those, :func:`.outliers.beyond_noise`)."""
        out = X.copy()
        out[self.points] -= self.put
        return out

    def describe(self) -> str:
        """The note for the report."""
        return (
            f"residual test: the displacement removed at {self.points.size} points "
            f"({100 * self.points.size / max(self.n, 1):.2g} %) was coherent shape, not noise "
            f"(neighbour correlation up to {self.rho_max:.2f}, noise stays below "
            f"{RHO_BACKOFF:g}): backed off there by "
            f"{self.restored_rms:.3g} RMS of the {self.removed_rms:.3g} removed"
        )


def _balls(L: sp.spmatrix, n: int, hops: int) -> sp.csr_matrix:
    S = abs(sp.csr_matrix(L, copy=True))  # never reorder the caller's L in place
    A = ((S + S.T) + sp.identity(n, format="csr")).astype(bool).astype(np.float64).tocsr()
    B = A
    for _ in range(hops - 1):
        B = (B @ A).astype(bool).astype(np.float64).tocsr()
    return B


def correlation(R: Array, L: sp.spmatrix, use: NDArray[np.bool_], hops: int = HOPS) -> Array:
    """Local neighbour correlation of the removed field: over each point's ball of ``hops``
    hops, ``sum_j R_j . (sum_{k ~ j} R_k) / sum_j deg_j |R_j|^2`` (``k ~ j``: graph
    neighbours, points ``use`` only): about 0 or below for removed noise (a high-pass of
    white noise), near 1 for removed shape."""
    n = R.shape[0]
    S = abs(sp.csr_matrix(L, copy=True))  # never reorder the caller's L in place
    A = ((S + S.T) != 0).astype(np.float64).tocsr()
    A.setdiag(0.0)
    A.eliminate_zeros()
    U = sp.diags(use.astype(np.float64))
    A = U @ A @ U
    Ru = np.where(use[:, None], R, 0.0)
    deg = np.asarray(A.sum(axis=1)).ravel()
    num = np.sum(Ru * (A @ Ru), axis=1)
    den = deg * np.sum(Ru**2, axis=1)
    B = _balls(L, n, hops)
    bn, bd = B @ num, B @ den
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = bn / bd
    return np.where(np.isfinite(rho) & (bd > 0), rho, 0.0)


def beyond_noise(R: Array, L: sp.spmatrix, use: NDArray[np.bool_], sigma: Array | float,
                 codim: int) -> Array:
    """``|R_i| / (z sigma_i)``: the removed displacement against the noise's Gaussian extreme
    ``z`` over ``n`` points (Bonferroni, :data:`ALPHA`; ``codim`` normal directions); 0 where
    fewer than :data:`CLUSTER` graph neighbours are beyond it too (an extreme of the noise is a
    point, a cut crease or pressed step a line of them)."""
    n = R.shape[0]
    from scipy.special import gammainccinv  # chi2.isf(q, k) = 2 Q^-1(k/2, q): no scipy.stats

    z = float(np.sqrt(2.0 * gammainccinv(max(codim, 1) / 2, ALPHA / max(n, 1))))
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.linalg.norm(R, axis=1) / (z * np.asarray(sigma))
    t = np.where(use & np.isfinite(t), t, 0.0)
    above = (t > 1.0).astype(np.float64)
    near = _balls(L, n, 1) @ above - above
    return np.where(near >= CLUSTER, t, 0.0)


def back_off(P: Array, X: Array, L: sp.spmatrix, exclude: NDArray[np.int64],
             fixed: NDArray[np.bool_], sigma: Array | float | None = None, codim: int = 1,
             ) -> tuple[Array, BackOff | None]:  # fmt: skip
    """``X`` with the removed displacement put back, in part, where the residual test says it
    was shape (module docstring; ``sigma``: the noise per point or for all, when estimated);
    ``None`` when nowhere."""
    use = ~fixed
    use[exclude] = False
    R = P - X
    rho = correlation(R, L, use)
    above = (rho > RHO_BACKOFF).astype(np.float64)
    near = _balls(L, X.shape[0], 1) @ above - above  # graph neighbours also above
    gate = np.clip(2.0 * (rho - RHO_BACKOFF) / (1.0 - RHO_BACKOFF), 0.0, 1.0) * use
    gate[near < CLUSTER] = 0.0
    if sigma is not None and np.all(np.asarray(sigma) > 0):
        t = beyond_noise(R, L, use, sigma, codim)
        gate = np.maximum(gate, np.clip(2.0 * (t - 1.0), 0.0, 1.0))
    hit = np.flatnonzero(gate > 0)
    if hit.size == 0:
        return X, None
    put = gate[hit, None] * R[hit]
    out = X.copy()
    out[hit] += put
    rec = BackOff(hit, float(rho.max()), float(np.sqrt(np.mean(np.sum(put**2, axis=1)))),
                  float(np.sqrt(np.mean(np.sum(R[hit] ** 2, axis=1)))), int(use.sum()), put)
    return out, rec
