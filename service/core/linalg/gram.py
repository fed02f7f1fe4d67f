"""``M = A^T A`` kept as ``A`` until a direct solver needs it formed."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

__all__ = ["Gram", "explicit"]

Array = NDArray[np.float64]


class Gram:
    """``M = A^T A`` kept as ``A``: products cost ``2 nnz(A)`` and ``M`` is formed on demand.

    With ``k`` neighbours per row ``A^T A`` has about ``k^2`` entries per row (k-NN with
    ``k = 64``: ~4000), so the matrix-free path never forms it.

    Parameters
    ----------
    A : sparse matrix, shape (p, m)
    """

    def __init__(self, A: sp.spmatrix) -> None:
        self.A = sp.csr_matrix(A)
        self.AT = self.A.T.tocsr()
        self.shape = (self.A.shape[1], self.A.shape[1])
        self._M: sp.csr_matrix | None = None

    def __matmul__(self, X: Array) -> Array:
        return np.asarray(self.AT @ (self.A @ X))

    def diagonal(self) -> Array:
        """``diag(A^T A)``: squared column norms of ``A``."""
        return np.asarray(self.A.multiply(self.A).sum(axis=0)).ravel()

    @property
    def nnz(self) -> int:
        """Entries of ``A`` (zero exactly when ``M = A^T A`` is zero)."""
        return int(self.A.nnz)

    def nnz_bound(self) -> int:
        """Upper bound of ``nnz(A^T A)``: the sum of squared row counts of ``A``."""
        return int(np.sum(np.diff(self.A.indptr).astype(np.int64) ** 2))

    def abs_row_sums(self, scale: Array) -> Array:
        """Row sums of ``|S A^T A S|`` bounded by ``S |A|^T |A| S 1`` (Gershgorin)."""
        absA = abs(self.A)
        return np.asarray(scale * (absA.T @ (absA @ scale))).ravel()

    def columns(self, idx: NDArray[np.int64]) -> Gram:
        """``M[idx][:, idx] = A[:, idx]^T A[:, idx]``."""
        return Gram(self.A[:, idx])

    def tocsr(self) -> sp.csr_matrix:
        """``A^T A`` formed (cached)."""
        if self._M is None:
            M = (self.AT @ self.A).tocsr()
            M.eliminate_zeros()
            self._M = M
        return self._M


def explicit(M: sp.spmatrix | Gram) -> sp.csr_matrix:
    """``M`` as a CSR matrix (forms a :class:`Gram`)."""
    return M.tocsr() if isinstance(M, Gram) else sp.csr_matrix(M)
