"""The max-norm bound's last resort (report section 9): points still beyond ``max_deviation``
after the reweighting of :func:`service.core.search.maxnorm.bound_deviation` are moved back
onto it."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["clip_points"]

Array = NDArray[np.float64]


def clip_points(P: Array, X: Array, delta: float) -> tuple[Array, int]:
    """Move every ``x_i`` with ``||x_i - p_i|| > delta`` radially back within ``delta``.

    Distances are those of the returned floating-point arrays: a point that rounding would
    still leave beyond the bound (``delta`` below a few ulps of ``|p_i|``) stays at ``p_i``.
    Returns the points and how many were moved.
    """
    X = X.copy()
    norms = np.linalg.norm(X - P, axis=1)
    over = np.flatnonzero(norms > delta)
    if over.size:
        shrink = delta / norms[over] * (1.0 - 1e-12)
        X[over] = P[over] + (X[over] - P[over]) * shrink[:, None]
        still = over[np.linalg.norm(X[over] - P[over], axis=1) > delta]
        X[still] = P[still]
    return X, int(over.size)
