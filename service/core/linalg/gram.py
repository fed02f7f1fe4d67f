"""``M = A^T A`` kept as ``A`` until a direct solver needs it formed.

Products of a large ``A`` whose entries lie far from its diagonal (a point cloud in the order it
was read: 70 ms a product at 1M points, 3x a mesh's with as many entries) are made on a copy
of ``A`` in reverse Cuthill-McKee order (:data:`LOCALITY_FROM`, issue 39 item 2): the vector
is gathered into that order and back, each row's entries summed in their original order, so
the products are the same to the bit.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

__all__ = ["LOCALITY_FROM", "Gram", "explicit"]

Array = NDArray[np.float64]
#: Unknowns from which a square ``A`` whose median entry lies more than ``1 / SCATTERED`` of the
#: size off the diagonal is reordered for its products.
LOCALITY_FROM = 100_000
SCATTERED = 64


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
        self.shape = (self.A.shape[1], self.A.shape[1])
        self._M: sp.csr_matrix | None = None
        self._local = _local_copies(self.A)
        self.AT = self.A.T.tocsr() if self._local is None else None

    def __matmul__(self, X: Array) -> Array:
        if self._local is None:
            return np.asarray(self.AT @ (self.A @ X))
        perm, inv, A, AT = self._local
        out = np.asarray(AT @ (A @ np.take(X, perm, axis=0)))
        return np.take(out, inv, axis=0)  # (np.take: 3x faster than fancy indexing here)

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
            M = ((self.A.T.tocsr() if self.AT is None else self.AT) @ self.A).tocsr()
            M.eliminate_zeros()
            self._M = M
        return self._M


def _local_copies(A: sp.csr_matrix) -> tuple[Any, ...] | None:
    """``(perm, inv, A', A'^T)`` with ``A' = A[perm][:, perm]`` in reverse Cuthill-McKee order
    for a large square ``A`` whose entries are scattered (else ``None``)."""
    m = A.shape[0]
    if m < LOCALITY_FROM or A.shape[1] != m or A.nnz == 0:
        return None
    at = np.arange(0, A.nnz, max(A.nnz // 20000, 1))
    rows = np.searchsorted(A.indptr, at, side="right") - 1
    if np.median(np.abs(A.indices[at] - rows)) * SCATTERED <= m:
        return None
    from scipy.sparse.csgraph import reverse_cuthill_mckee

    # A's own pattern (nearly symmetric; any order gives the same products): no A + A^T (0.5 s)
    perm = reverse_cuthill_mckee(A, symmetric_mode=True).astype(np.int64)
    inv = np.empty_like(perm)
    inv[perm] = np.arange(m)
    return perm, inv, _renamed(A, perm, inv), _renamed(A.T.tocsr(), perm, inv)


def _renamed(A: sp.csr_matrix, perm: NDArray[np.int64], inv: NDArray[np.int64]) -> sp.csr_matrix:
    """``A[perm][:, perm]`` with each row's entries in their original order (not sorted)."""
    lengths = np.diff(A.indptr)[perm]
    indptr = np.r_[0, np.cumsum(lengths)].astype(A.indptr.dtype)
    take = np.repeat(A.indptr[perm] - indptr[:-1], lengths) + np.arange(indptr[-1])
    indices = inv[A.indices[take]].astype(A.indices.dtype)
    return sp.csr_matrix((A.data[take], indices, indptr), shape=A.shape)


def explicit(M: sp.spmatrix | Gram) -> sp.csr_matrix:
    """``M`` as a CSR matrix (forms a :class:`Gram`)."""
    return M.tocsr() if isinstance(M, Gram) else sp.csr_matrix(M)
