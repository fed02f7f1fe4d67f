"""Per-point noise ``sigma_i`` for uneven noise (issue 21) and the checks that keep it from
firing on shape: the crease correction of the budget and quantized coordinates (issue 31).

Used by :func:`service.core.noise.robust.data_weights`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from service.core.noise.quantiles import chi2

__all__ = ["CREASE_MEDIAN", "QUANTILE", "RATIO_CAP", "crease_factor", "local_sigma", "on_grid",
           "row_quantile"]

Array = NDArray[np.float64]
#: Bounds of ``sigma_i / sigma`` (the spread cap): a point's share of the automatic budget
#: ``(omega_i sigma_i / sigma)^2 = sigma_i / sigma`` is at most this many times the mean's, so
#: one region cannot take the budget (issue 31).
RATIO_CAP = 4.0
#: ``median(sigma_i) / sigma`` below this: the estimate's mode came from crease-straddling
#: fits (calibration half: the step block's 3.4x over-estimates 0.49 - 0.52; every other case,
#: uniform, varying, quantized or 1 h noise, 0.85 - 2.16).
CREASE_MEDIAN = 0.67
#: Quantile of the neighbourhood's ``v_j`` that estimates ``sigma_i^2``.
QUANTILE = 0.25


def crease_factor(sig: Array, sigma: float) -> float:
    """The budget's correction when the global estimate was taken from fits that straddle
    creases (issue 31): ``median(sigma_i) / sigma`` below :data:`CREASE_MEDIAN` says the mode
    of the residual variances sits on the crease band, not on the faces; the budget then uses
    the lower quartile of ``sigma_i`` (the least crease-affected level), else 1."""
    with np.errstate(all="ignore"):
        med = float(np.nanmedian(sig)) / sigma if sigma > 0 else np.nan
        low = float(np.nanquantile(sig, 0.25)) / sigma if sigma > 0 else np.nan
    if not (np.isfinite(med) and np.isfinite(low)) or med >= CREASE_MEDIAN:
        return 1.0
    return float(np.clip(low, 1.0 / RATIO_CAP, 1.0))


def on_grid(P: Array, sigma: float, share: float = 0.5) -> bool:
    """Whether the coordinates are quantized at a step of at least ``sigma``: on some axis the
    points take fewer than ``share * n`` distinct values, all on multiples of one step (a
    scan stored at 1 mm with 5 cm noise is not: no terraces form). Quantization leaves exactly
    flat terraces where the surface runs along the grid (zero fit residuals, a spread of
    ``log sigma_i`` of 5 - 18) while its noise is one level everywhere (issue 31)."""
    n = P.shape[0]
    for col in P.T:
        u = np.unique(col)
        if u.size < 3 or u.size >= share * n:
            continue
        gaps = np.diff(u)
        step = float(gaps.min())
        if step >= sigma and np.all(np.abs(gaps / step - np.round(gaps / step)) < 1e-3):
            return True
    return False


def local_sigma(v: Array, nbr: NDArray[np.int64], nu: int) -> Array:
    """``sigma_i``: the lower quartile of ``v`` over each row of ``nbr`` over that of
    ``chi^2_nu / nu`` (a crease or an outlier raises the fits that straddle it, not the
    quartile), then the mean of its logarithm over the row, twice (robust, then smooth)."""
    with np.errstate(all="ignore"):
        s2 = row_quantile(v[nbr], QUANTILE) / (chi2.ppf(QUANTILE, nu) / nu)
        logs = np.log(np.where(s2 > 0, s2, np.nan))
        for _ in range(2):  # nanmean's sum / count, without its warning for all-NaN rows
            rows = logs[nbr]
            logs = np.where(np.isnan(rows), 0.0, rows).sum(axis=1) / (~np.isnan(rows)).sum(axis=1)
    return np.sqrt(np.exp(logs))


def row_quantile(A: Array, q: float) -> Array:
    """The ``q`` quantile (linear interpolation) of each row's finite values (``nan`` for a
    row without any): ``np.nanquantile(A, q, axis=1)`` without its per-row loop."""
    B = np.sort(np.where(np.isfinite(A), A, np.inf), axis=1)
    m = np.sum(np.isfinite(A), axis=1)
    pos = q * np.maximum(m - 1, 0)
    lo = np.floor(pos).astype(np.int64)
    hi = np.minimum(lo + 1, np.maximum(m - 1, 0))
    rows = np.arange(A.shape[0])
    with np.errstate(invalid="ignore"):
        out = B[rows, lo] + (pos - lo) * (B[rows, hi] - B[rows, lo])
    return np.where(m > 0, out, np.nan)
