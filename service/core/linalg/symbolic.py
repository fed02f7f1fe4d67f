"""Compiled kernel of :func:`service.core.linalg.resources.factor_size` (numba).

Sequential by nature (a walk up the elimination tree per row); numpy cannot vectorize it.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["colcounts"]


@njit(cache=True)
def colcounts(n: int, indptr: np.ndarray, indices: np.ndarray) -> np.ndarray:  # pragma: no cover
    """Column counts (diagonal included) of the Cholesky factor of a symmetric pattern.

    Parameters
    ----------
    n : int
    indptr, indices : ndarray of int64
        CSR of the strictly lower triangle, sorted.
    """
    parent = np.full(n, -1, np.int64)
    ancestor = np.full(n, -1, np.int64)
    for i in range(n):  # elimination tree, Liu's algorithm with path compression
        for p in range(indptr[i], indptr[i + 1]):
            r = indices[p]
            while r != -1 and r < i:
                nxt = ancestor[r]
                ancestor[r] = i
                if nxt == -1:
                    parent[r] = i
                r = nxt
    counts = np.ones(n, np.int64)
    mark = np.full(n, -1, np.int64)
    for i in range(n):  # row subtrees: L[i, r] != 0 for every r on the paths up to i
        mark[i] = i
        for p in range(indptr[i], indptr[i + 1]):
            r = indices[p]
            while r != -1 and mark[r] != i:
                counts[r] += 1
                mark[r] = i
                r = parent[r]
    return counts
