"""The chi-square and Poisson quantiles of the data weights (:mod:`.robust`) through the
special functions ``scipy.stats`` calls for them: the same numbers
(``tests/core/noise/test_stats_free.py``) without importing ``scipy.stats``, which took
0.2-0.6 s of every run's start (issue 30)."""

from __future__ import annotations

import math

from scipy import special

__all__ = ["chi2", "poisson_ppf"]


class _Chi2:
    """``scipy.stats.chi2``'s ``isf``, ``ppf``, ``median`` and ``sf``."""

    @staticmethod
    def isf(q: float, df: float) -> float:
        return float(special.chdtri(df, q))

    @staticmethod
    def ppf(q: float, df: float) -> float:
        return float(2 * special.gammaincinv(df / 2, q))

    @staticmethod
    def median(df: float) -> float:
        return float(2 * special.gammaincinv(df / 2, 0.5))

    @staticmethod
    def sf(x: float, df: float) -> float:
        return float(special.chdtrc(df, x))


chi2 = _Chi2()


def poisson_ppf(q: float, mu: float) -> float:
    """``scipy.stats.poisson.ppf(q, mu)`` (its ``_ppf``: the same numbers)."""
    vals = math.ceil(special.pdtrik(q, mu))
    below = max(vals - 1, 0)
    return float(below if special.pdtr(below, mu) >= q else vals)
