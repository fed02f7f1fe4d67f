"""The data weights' chi-square and Poisson quantiles without importing scipy.stats (issue 30:
start-up) are scipy.stats' numbers exactly."""

from __future__ import annotations

import pytest
from scipy.stats import chi2 as stats_chi2
from scipy.stats import poisson

from service.core.noise import quantiles


@pytest.mark.parametrize("df", [1, 2, 3, 5, 9, 14, 33, 100])
def test_chi2_is_scipy_stats(df: int) -> None:
    chi2 = quantiles.chi2
    for q in (1e-4, 1e-3, 0.25, 0.5):
        assert chi2.isf(q, df) == stats_chi2.isf(q, df)
        assert chi2.ppf(q, df) == stats_chi2.ppf(q, df)
    assert chi2.median(df) == stats_chi2.median(df)
    for x in (0.1, 3.0, 30.0, 100.0):
        assert chi2.sf(x, df) == stats_chi2.sf(x, df)


@pytest.mark.parametrize("mu", [0.01, 0.5, 1.0, 4.1, 16.4, 100.0, 1000.0])
def test_poisson_ppf_is_scipy_stats(mu: float) -> None:
    assert quantiles.poisson_ppf(0.999, mu) == poisson.ppf(0.999, mu)
