"""Compiled leave-one-out fits of surfaces in 3-D (issue 30: the data weights at 1M).

The same numbers as :func:`service.core.noise.pointfits.leave_one_out` (its docstring defines
``r_i`` and ``v_i``) for the case that dominates the default's cost, surfaces in 3-D
(``s = 3``, ``d = 2``, one normal direction), one point at a time in numba instead of batched
``(chunk, k, 3)`` NumPy arrays (``eigh`` and ``inv`` of stacks, temporaries of ``k x 6``
design matrices). Two changes of arithmetic, neither of the result:

* the local frame needs only the normal: the quadratic height function's space
  ``{1, u_1, u_2, u_1^2, u_1 u_2, u_2^2}`` and the scale ``sqrt(sum |u|^2 / (2 m))`` are invariant
  under rotations of the tangent basis, so any orthonormal tangent pair gives the same residuals.
  The normal is the eigenvector of the smallest eigenvalue of the neighbours' 3 x 3 covariance,
  from the closed-form eigenvalues (Smith 1961) and the largest cross product of two rows of
  ``C - mu_3 I``; the tangent variances ``mu_1 >= mu_2`` feed the same degeneracy test;
* the 6 x 6 normal equations are solved through their Cholesky factor and its inverse
  ``L^-1`` (``h_i = |L^-1 b_i|^2``); the NumPy path's check of the inverse
  (``max |G^-1 G - I| < 1e-6``, else ``nan``) runs only where it could fail, when
  ``kappa = |G|_F tr(G^-1) >= cond_2(G)`` reaches :data:`CERTAIN` (issue 30: the check and the
  explicit inverse were half of the fit's arithmetic).

They agree with the NumPy path to rounding (tests: relative differences ~1e-12 on ``r`` and
``v``, identical outlier decisions). Other dimensions fall back to the NumPy path.
:func:`patch_variances` does the same for the noise estimate's fits
(:func:`service.core.noise.pointfits.patch_variances`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from service.core.noise.local3 import centred_covariance, eig3, tangent_pair

__all__ = ["CERTAIN", "leave_one_out", "patch_variances"]

Array = NDArray[np.float64]
#: Bound on ``cond_2`` of the normal equations below which their inverse needs no check.
CERTAIN = 1e6


def leave_one_out(
    points: Array,
    nbr: NDArray[np.int64],
    manifold_dim: int,
    use: NDArray[np.bool_] | None = None,
) -> tuple[Array, Array]:
    """``(r, v)`` as :func:`service.core.noise.pointfits.leave_one_out` (same arguments) for
    surfaces in 3-D (the only case its callers send: other dimensions are a ``ValueError``;
    this module imports no other of the package, so the noise estimate can use it)."""
    if points.shape[1] != 3 or manifold_dim != 2:
        raise ValueError("compiled fits are for surfaces in 3-D (manifold_dim 2, 3 coordinates)")
    m = nbr.shape[0]
    r = np.full(m, np.nan)
    v = np.full(m, np.nan)
    W = np.ones((0, 0)) if use is None else use.astype(np.float64)  # empty: all neighbours
    P = np.ascontiguousarray(points, dtype=np.float64)
    _surface_fits(P, np.ascontiguousarray(nbr, dtype=np.int64), np.ascontiguousarray(W), r, v)
    return r, v


@njit(cache=True)
def _surface_fits(
    P: Array, nbr: NDArray[np.int64], W: Array, r: Array, v: Array
) -> None:  # pragma: no cover
    """The fits of every row of ``nbr`` (column 0 the point), into ``r`` and ``v``; ``W`` the
    neighbours' weights (0 or 1), or empty for all 1."""
    m, kk = nbr.shape
    weighted = W.shape[0] == m
    npar = 6
    B = np.empty((kk, npar))
    z = np.empty(kk)
    G = np.empty((npar, npar))
    L = np.empty((npar, npar))
    Li = np.zeros((npar, npar))
    Gi = np.empty((npar, npar))
    rhs = np.empty(npar)
    b0 = np.empty(npar)
    y = np.empty(npar)
    coef = np.empty(npar)
    for i in range(m):
        cnt = mx = my = mz = 0.0
        for t in range(1, kk):
            w, j = (W[i, t - 1] if weighted else 1.0), nbr[i, t]
            cnt += w
            mx += w * P[j, 0]
            my += w * P[j, 1]
            mz += w * P[j, 2]
        den = max(cnt, 1.0)
        mx, my, mz = mx / den, my / den, mz / den
        c00 = c01 = c02 = c11 = c12 = c22 = 0.0
        for t in range(1, kk):
            w, j = (W[i, t - 1] if weighted else 1.0), nbr[i, t]
            qx, qy, qz = P[j, 0] - mx, P[j, 1] - my, P[j, 2] - mz
            c00 += w * qx * qx
            c01 += w * qx * qy
            c02 += w * qx * qz
            c11 += w * qy * qy
            c12 += w * qy * qz
            c22 += w * qz * qz
        mu1, mu2, nx, ny, nz = eig3(c00, c01, c02, c11, c12, c22)
        if not (cnt - npar >= 1.0 and mu2 > 1e-8 * max(mu1, 1e-300)) or nx == ny == nz == 0.0:
            continue
        t1x, t1y, t1z, t2x, t2y, t2z = tangent_pair(nx, ny, nz)
        ss = 0.0
        for t in range(1, kk):
            j = nbr[i, t]
            qx, qy, qz = P[j, 0] - mx, P[j, 1] - my, P[j, 2] - mz
            u1 = qx * t1x + qy * t1y + qz * t1z
            u2 = qx * t2x + qy * t2y + qz * t2z
            B[t, 1], B[t, 2] = u1, u2
            z[t] = qx * nx + qy * ny + qz * nz
            ss += (W[i, t - 1] if weighted else 1.0) * (u1 * u1 + u2 * u2)
        scale = math.sqrt(ss / max(cnt * 2.0, 1.0))
        if not scale > 0.0:
            scale = 1.0
        G[:, :] = 0.0
        rhs[:] = 0.0
        for t in range(1, kk):
            u1, u2 = B[t, 1] / scale, B[t, 2] / scale
            B[t, 0], B[t, 1], B[t, 2] = 1.0, u1, u2
            B[t, 3], B[t, 4], B[t, 5] = u1 * u1, u1 * u2, u2 * u2
            w = W[i, t - 1] if weighted else 1.0
            for a in range(npar):
                wa = w * B[t, a]
                rhs[a] += wa * z[t]
                for b in range(a, npar):
                    G[a, b] += wa * B[t, b]
        for a in range(npar):
            for b in range(a):
                G[a, b] = G[b, a]
        kappa = _factor(G, L, Li, y)
        if kappa < 0.0 or (kappa >= CERTAIN and not _inverse_ok(G, Li, Gi)):
            continue
        qx, qy, qz = P[nbr[i, 0], 0] - mx, P[nbr[i, 0], 1] - my, P[nbr[i, 0], 2] - mz
        u1 = (qx * t1x + qy * t1y + qz * t1z) / scale
        u2 = (qx * t2x + qy * t2y + qz * t2z) / scale
        b0[0], b0[1], b0[2], b0[3], b0[4], b0[5] = 1.0, u1, u2, u1 * u1, u1 * u2, u2 * u2
        _solve(Li, rhs, y, coef)
        rss = 0.0
        for t in range(1, kk):
            e = z[t]
            for a in range(npar):
                e -= B[t, a] * coef[a]
            rss += (W[i, t - 1] if weighted else 1.0) * e * e
        v[i] = rss / (cnt - npar)
        e0 = qx * nx + qy * ny + qz * nz
        h0 = 0.0
        for a in range(npar):  # h0 = b0^T G^-1 b0 = |L^-1 b0|^2
            e0 -= b0[a] * coef[a]
            lb = 0.0
            for b in range(a + 1):
                lb += Li[a, b] * b0[b]
            h0 += lb * lb
        r[i] = e0 * e0 / (1.0 + h0)


@njit(cache=True)
def _factor(G: Array, L: Array, Li: Array, y: Array) -> float:  # pragma: no cover
    """Cholesky ``G = L L^T`` and ``Li = L^-1`` (lower triangle; ``y`` work space); returns
    ``kappa = |G|_F |L^-1|_F^2 = |G|_F tr(G^-1)``, which lies in ``[cond_2(G), 6 sqrt(6)
    cond_2(G)]``, or -1 when ``G`` is not definite to rounding."""
    n = G.shape[0]
    for j in range(n):
        s = G[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:
            return -1.0
        L[j, j] = math.sqrt(s)
        for i in range(j + 1, n):
            s = G[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / L[j, j]
    li2 = 0.0
    for col in range(n):  # L^-1 column by column
        y[col] = 1.0 / L[col, col]
        for i in range(col + 1, n):
            s = 0.0
            for k in range(col, i):
                s -= L[i, k] * y[k]
            y[i] = s / L[i, i]
        for i in range(col, n):
            Li[i, col] = y[i]
            li2 += y[i] * y[i]
    g2 = 0.0
    for a in range(n):
        for b in range(n):
            g2 += G[a, b] * G[a, b]
    return math.sqrt(g2) * li2


@njit(cache=True)
def _inverse_ok(G: Array, Li: Array, Gi: Array) -> bool:  # pragma: no cover
    """The NumPy path's check of the inverse, ``max |G^-1 G - I| < 1e-6``, with
    ``G^-1 = L^-T L^-1``. Needed only when :func:`_factor`'s ``kappa`` reaches
    :data:`CERTAIN`: below, the computed inverse's error is at most ``c n eps kappa``
    (backward stable Cholesky, ``c n <= 36``), under 1e-8."""
    n = G.shape[0]
    for a in range(n):
        for b in range(a, n):
            s = 0.0
            for k in range(b, n):
                s += Li[k, a] * Li[k, b]
            Gi[a, b] = s
            Gi[b, a] = s
    for a in range(n):
        for b in range(n):
            s = 0.0
            for k in range(n):
                s += Gi[a, k] * G[k, b]
            if not abs(s - (1.0 if a == b else 0.0)) < 1e-6:
                return False
    return True


@njit(cache=True)
def _solve(Li: Array, rhs: Array, y: Array, coef: Array) -> None:  # pragma: no cover
    """``coef = G^-1 rhs = L^-T (L^-1 rhs)``."""
    n = Li.shape[0]
    for a in range(n):
        s = 0.0
        for b in range(a + 1):
            s += Li[a, b] * rhs[b]
        y[a] = s
    for a in range(n):
        s = 0.0
        for b in range(a, n):
            s += Li[b, a] * y[b]
        coef[a] = s


def patch_variances(
    points: Array, neighbours: NDArray[np.int64]
) -> tuple[Array, NDArray[np.bool_]]:
    """:func:`service.core.noise.pointfits.patch_variances` of surfaces in 3-D (quadratic
    height functions; the point is one of its neighbourhood's fits), one row at a time: the
    normal from :func:`~service.core.noise.local3.eig3`, any tangent pair (the module
    docstring), the normal equations through Cholesky. Its ``cond(G) < 1e10`` test:
    ``kappa = |G|_F tr(G^-1)`` lies in ``[cond, 6 sqrt(6) cond]``, so rows with
    ``kappa < 1e9`` pass and rows with ``kappa > 1.5e11`` fail for sure. Returns ``v`` and the
    rows between (and any without a normal), which the caller measures with the NumPy code."""
    P = np.ascontiguousarray(points, dtype=np.float64)
    nbr = np.ascontiguousarray(neighbours, dtype=np.int64)
    v = np.full(nbr.shape[0], np.nan)
    unsure = np.zeros(nbr.shape[0], dtype=np.bool_)
    _patch_fits(P, nbr, v, unsure)
    return v, unsure


@njit(cache=True)
def _patch_fits(
    P: Array, nbr: NDArray[np.int64], v: Array, unsure: NDArray[np.bool_]
) -> None:  # pragma: no cover
    """The fits of :func:`patch_variances`, into ``v`` (``unsure`` where the NumPy path
    decides)."""
    m, kk = nbr.shape
    npar = 6
    B = np.empty((kk, npar))
    z = np.empty(kk)
    G = np.empty((npar, npar))
    L = np.empty((npar, npar))
    Li = np.zeros((npar, npar))
    rhs = np.empty(npar)
    y = np.empty(npar)
    coef = np.empty(npar)
    for i in range(m):
        mx, my, mz, c00, c01, c02, c11, c12, c22 = centred_covariance(P, nbr[i], kk)
        _, _, nx, ny, nz = eig3(c00, c01, c02, c11, c12, c22)
        if nx == ny == nz == 0.0:
            unsure[i] = True
            continue
        t1x, t1y, t1z, t2x, t2y, t2z = tangent_pair(nx, ny, nz)
        ss = 0.0
        for t in range(kk):
            j = nbr[i, t]
            qx, qy, qz = P[j, 0] - mx, P[j, 1] - my, P[j, 2] - mz
            B[t, 1] = qx * t1x + qy * t1y + qz * t1z
            B[t, 2] = qx * t2x + qy * t2y + qz * t2z
            z[t] = qx * nx + qy * ny + qz * nz
            ss += B[t, 1] * B[t, 1] + B[t, 2] * B[t, 2]
        scale = math.sqrt(ss / (2.0 * kk))
        if not scale > 0.0:
            scale = 1.0
        G[:, :] = 0.0
        rhs[:] = 0.0
        for t in range(kk):
            u1, u2 = B[t, 1] / scale, B[t, 2] / scale
            B[t, 0], B[t, 1], B[t, 2] = 1.0, u1, u2
            B[t, 3], B[t, 4], B[t, 5] = u1 * u1, u1 * u2, u2 * u2
            for a in range(npar):
                rhs[a] += B[t, a] * z[t]
                for b in range(a, npar):
                    G[a, b] += B[t, a] * B[t, b]
        for a in range(npar):
            for b in range(a):
                G[a, b] = G[b, a]
        kappa = _factor(G, L, Li, y)
        if kappa < 0.0 or 1e9 <= kappa <= 1.5e11:  # not definite to rounding, or unsure
            unsure[i] = True
            continue
        if kappa > 1.5e11:
            continue
        _solve(Li, rhs, y, coef)
        rss = 0.0
        for t in range(kk):
            e = z[t]
            for a in range(npar):
                e -= B[t, a] * coef[a]
            rss += e * e
        v[i] = rss / (kk - npar)
