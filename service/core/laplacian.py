"""The generalized Laplacian variants of report section 4.1.

* ``L^(n) = I - W``: normalized, unit diagonal (eq. 1) for every point with neighbours; rows of
  points without neighbours are zero, so such points pass through smoothing unchanged.
* ``L^(kappa)_i = g(||L^(n)_i P||) kappa_i L^(n)_i`` (eqs. 7-9): curvature scaled, with the Huber
  function ``g`` of eq. (8) (its threshold floored relative to the data, see
  :func:`effective_sigma_h`).
* ``L^(f)_i = g(||L^(n)_i P||) psi(kappa~_i) L^(n)_i`` (eq. 10): feature preserving, with the
  Gaussian ``psi(k) = exp(-k^2 / (2 sigma_f^2))`` on curvatures rescaled to [0, 1].
"""

from __future__ import annotations

from typing import Literal

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

__all__ = ["effective_sigma_h", "huber_g", "laplacian", "normalized_laplacian", "row_scales"]


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
