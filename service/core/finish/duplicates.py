"""Exact duplicates end exactly together (issue 40).

Points with the same input coordinates (a photogrammetric cloud's repeated matches, an STL's
split vertices) are one sample of the surface: the solve moves each copy with its own row and
neighbours, so copies drift apart (0.05 spacings on a sphere cloud with 0.5 % duplicates). Each
group of copies gets its members' mean; a group with a fixed member keeps that member's (input)
position, as every fixed point does.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["join_duplicates"]

Array = NDArray[np.float64]


def _groups(P: Array) -> tuple[NDArray[np.int64], NDArray[np.int64]] | None:
    """Rows of ``P`` with a copy and their group label (``None`` when all rows differ)."""
    order = np.lexsort(P.T[::-1])
    S = P[order]
    same = np.all(S[1:] == S[:-1], axis=1)
    if not same.any():
        return None
    start = np.r_[True, ~same]
    label = np.cumsum(start) - 1
    size = np.bincount(label)
    dup = size[label] > 1
    return order[dup], label[dup]


def join_duplicates(P: Array, X: Array, fixed: NDArray[np.bool_]) -> Array:
    """``X`` with every group of identical rows of ``P`` at one position (module docstring)."""
    got = _groups(P)
    if got is None:
        return X
    rows, label = got
    _, label = np.unique(label, return_inverse=True)
    m = int(label.max()) + 1
    count = np.bincount(label, minlength=m).astype(np.float64)
    sums = [np.bincount(label, X[rows, a], minlength=m) for a in range(X.shape[1])]
    mean: Array = np.stack(sums, 1).astype(np.float64) / count[:, None]
    pinned = np.zeros(m, dtype=bool)
    pinned[label[fixed[rows]]] = True
    member = np.empty(m, dtype=np.int64)
    member[label] = rows  # any member: the copies' input rows are identical
    mean[pinned] = P[member[pinned]]
    out = X.copy()
    out[rows] = mean[label]
    return out
