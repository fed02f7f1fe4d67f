"""The generalized Laplacian variants of report section 4.1.

* ``L^(n) = I - W``: normalized, unit diagonal (eq. 1) for every point with neighbours; rows of
  points without neighbours are zero, so such points pass through smoothing unchanged.
* ``L^(kappa)_i = g(||L^(n)_i P||) kappa_i L^(n)_i`` (eqs. 7-9): curvature scaled, with the Huber
  function ``g`` of eq. (8) (its threshold floored relative to the data, see
  :func:`effective_sigma_h`).
* ``L^(f)_i = g(||L^(n)_i P||) psi(kappa~_i) L^(n)_i`` (eq. 10): feature preserving, with the
  Gaussian ``psi(k) = exp(-k^2 / (2 sigma_f^2))`` on curvatures rescaled to [0, 1].

On noisy input ``||L^(n)_i P||`` and ``kappa_i`` measure the noise more than the shape: the
scaled rows then weaken the smoothing exactly where the noise is largest, and L(f) kept the
creases of ``fandisk.obj`` *worse* than L(n) (issue 9). The engine therefore evaluates ``g`` and
``kappa`` on a pre-smoothed copy of the input (:func:`presmooth`, ``SmoothingParams.presmooth``
steps, default 2; 0 reproduces the report): on ``fandisk.obj`` with noise 0.25 h along the
normals, at equal tau = 0.6 n sigma^2, the RMS vertex error of the points within two edge lengths
of a crease is 0.628 of the input's with L(f) against 0.673 with L(n) (0.754 with the report's
L(f)); with noise 0.1 h (normal + tangential) 0.724 against 0.965. It does not help with
isotropic noise of 0.5 h (0.700 against 0.634); see ``benchmarks/quality/README.md``.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

__all__ = [
    "PRESMOOTH_STEPS",
    "effective_sigma_h",
    "huber_g",
    "laplacian",
    "normalized_laplacian",
    "presmooth",
    "row_scales",
    "without_junction_rows",
]

#: Default averaging steps before the curvature and the L(kappa)/L(f) row scales are computed
#: (``SmoothingParams.presmooth``; the report used 0); chosen on the quality benchmark.
PRESMOOTH_STEPS = 2


def huber_g(x: NDArray[np.float64], sigma_h: float) -> NDArray[np.float64]:
    """Huber edge-stopping function of eq. (8): ``1/sigma_h`` for ``x <= sigma_h``, else ``1/x``."""
    return 1.0 / np.maximum(x, sigma_h)


def effective_sigma_h(norms: NDArray[np.float64], sigma_h: float) -> float:
    """Huber threshold actually used: ``max(sigma_h, 1e-3 * median ||L^(n)_i P||)``.

    The report's absolute ``sigma_h = 1e-7`` assumes data of unit size. Exactly flat or
    duplicated points have ``||L^(n)_i P|| = 0`` and would get a row ``1e7`` times larger than a
    typical one, making eq. (17) numerically singular; the relative floor keeps the ratio of row
    scales below about 1e3 and makes the result independent of the unit of the coordinates.
    """
    nz = norms[norms > 0]
    return max(sigma_h, 1e-3 * float(np.median(nz))) if nz.size else sigma_h


def normalized_laplacian(W: sp.csr_matrix) -> sp.csr_matrix:
    """``L^(n) = I' - W`` with ``I'`` the identity on rows that have neighbours (eq. 1)."""
    has = (np.diff(W.indptr) > 0).astype(float)
    return (sp.diags(has) - W).tocsr()


def row_scales(
    Ln: sp.csr_matrix,
    points: NDArray[np.float64],
    variant: Literal["curvature", "feature"],
    kappa: NDArray[np.float64],
    sigma_h: float,
    sigma_f: float,
) -> NDArray[np.float64]:
    """Per-row factors turning ``L^(n)`` into ``L^(kappa)`` (eq. 9) or ``L^(f)`` (eq. 10).

    Parameters
    ----------
    Ln : scipy.sparse.csr_matrix
        Normalized Laplacian.
    points : ndarray, shape (n, s)
        Input points ``P``.
    variant : {"curvature", "feature"}
    kappa : ndarray, shape (n,)
        Curvature estimates.
    sigma_h, sigma_f : float
        Huber threshold (eq. 8) and Gaussian width (eq. 10).

    Returns
    -------
    ndarray, shape (n,)
    """
    norms = np.linalg.norm(Ln @ points, axis=1)
    g = huber_g(norms, effective_sigma_h(norms, sigma_h))
    if variant == "curvature":
        return g * kappa
    lo, hi = float(kappa.min()), float(kappa.max())
    k01 = (kappa - lo) / (hi - lo) if hi > lo else np.zeros_like(kappa)
    return g * np.exp(-0.5 * k01**2 / sigma_f**2)


def laplacian(
    W: sp.csr_matrix,
    points: NDArray[np.float64],
    variant: Literal["normalized", "curvature", "feature"],
    kappa: NDArray[np.float64] | None = None,
    sigma_h: float = 1e-7,
    sigma_f: float = 0.5,
) -> sp.csr_matrix:
    """Build ``L^(n)``, ``L^(kappa)`` or ``L^(f)`` (report section 4.1).

    Parameters
    ----------
    W : scipy.sparse.csr_matrix, shape (n, n)
        Row-stochastic neighbour weights.
    points : ndarray, shape (n, s)
    variant : {"normalized", "curvature", "feature"}
    kappa : ndarray, shape (n,), optional
        Needed for the scaled variants.
    sigma_h, sigma_f : float

    Returns
    -------
    scipy.sparse.csr_matrix, shape (n, n)
    """
    Ln = normalized_laplacian(W)
    if variant == "normalized":
        return Ln
    if kappa is None:
        raise ValueError("the scaled Laplacians need curvature estimates")
    scales = row_scales(Ln, points, variant, kappa, sigma_h, sigma_f)
    out = (sp.diags(scales) @ Ln).tocsr()
    out.eliminate_zeros()
    return out


def presmooth(
    points: NDArray[np.float64], adjacency: sp.csr_matrix, steps: int = PRESMOOTH_STEPS
) -> NDArray[np.float64]:
    """``steps`` averaging steps ``x <- (x + mean of neighbours) / 2`` (uniform weights)."""
    deg = np.asarray(adjacency.sum(axis=1)).ravel()
    inv = np.divide(1.0, deg, out=np.zeros_like(deg), where=deg > 0)
    W = sp.diags(inv) @ adjacency
    X = points.copy()
    has = deg > 0
    if has.all():  # the same numbers without the masked copies (issue 30)
        for _ in range(steps):
            X = 0.5 * (X + np.asarray(W @ X))
        return X
    for _ in range(steps):
        X[has] = 0.5 * (X[has] + np.asarray(W @ X)[has])
    return X


def without_junction_rows(L: sp.csr_matrix, adjacency: sp.csr_matrix) -> sp.csr_matrix:
    """``L`` with the rows of curve-network junctions (three or more neighbours) set to zero.

    A junction is a corner of the network: the curves that meet there are smoothed up to it
    (their rows still contain it), but no smoothness of its own pulls it towards the centroid
    of the branches, which would bend every branch at its end. On the quality benchmark's
    networks (a circle with two diameters in 2-D, a wire-frame cube in 3-D) this lowers the
    best RMS vertex error from 0.39 / 0.48 to 0.29 / 0.32 of the input's (PyVista's
    windowed-sinc: 0.37 / 0.40); see ``benchmarks/quality/README.md``.
    """
    deg = np.diff(sp.csr_matrix(adjacency).indptr)
    keep = (deg < 3).astype(float)
    if keep.all():
        return L
    out = (sp.diags(keep) @ L).tocsr()
    out.eliminate_zeros()
    return out
