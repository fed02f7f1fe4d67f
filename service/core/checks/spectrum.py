"""Spectral view of the smoothing as a low-pass filter (report section 5, eq. 12).

With ``D = I`` the solution of eq. (4) is ``X = sum_i v_i gamma_i v_i^T P`` with ``sigma_i, v_i``
the singular values and right singular vectors of ``L`` and the filter factors
``gamma_i = lambda / (sigma_i^2 + lambda)``. For general weights, substituting ``Y = D X`` turns
eq. (4) into the same problem for ``L D^-1``, whose singular values are the generalized singular
values of ``(L, D)``; then ``X = D^-1 sum_i v_i gamma_i v_i^T D P``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from service.core.params import SPECTRUM_MAX_POINTS

__all__ = ["SPECTRUM_MAX_POINTS", "Spectrum", "filter_factors", "singular_values"]


def _scaled(L: sp.spmatrix, omega: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.asarray((sp.csr_matrix(L) @ sp.diags(1.0 / omega)).toarray())


def singular_values(
    L: sp.spmatrix, omega: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Singular values (decreasing) and right singular vectors of ``L D^-1``.

    Parameters
    ----------
    L : sparse matrix, shape (m, n)
    omega : ndarray, shape (n,)
        Diagonal of ``D``.

    Returns
    -------
    sigma : ndarray, shape (n,)
        Padded with zeros when ``m < n``.
    V : ndarray, shape (n, n)
        Right singular vectors as columns.
    """
    A = _scaled(L, omega)
    _, s, vt = np.linalg.svd(A, full_matrices=True)
    sigma = np.zeros(A.shape[1])
    sigma[: s.size] = s
    return sigma, vt.T


def filter_factors(sigma: NDArray[np.float64], lam: float) -> NDArray[np.float64]:
    """``gamma_i = lambda / (sigma_i^2 + lambda)`` (eq. 12)."""
    return lam / (sigma**2 + lam)


@dataclass(frozen=True)
class Spectrum:
    """Spectral view of report section 5 (eq. 12).

    Attributes
    ----------
    sigma : ndarray
        Singular values of ``L`` (``D = I``) or generalized singular values of ``(L, D)``,
        in decreasing order.
    gamma : ndarray
        Filter factors ``gamma_i = lambda / (sigma_i^2 + lambda)`` at the chosen lambda.
    """

    sigma: NDArray[np.float64]
    gamma: NDArray[np.float64]

    def to_dict(self) -> dict[str, list[float]]:
        return {"sigma": self.sigma.tolist(), "gamma": self.gamma.tolist()}
