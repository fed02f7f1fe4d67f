"""The rational interpolation of report section 6.3."""

from __future__ import annotations

import math

import numpy as np

from service.core.search.roots import rational_step, search_lambda


def test_rational_step_is_exact_for_rational_functions() -> None:
    # phi(lam) = (u lam + v) / (lam + w) is reproduced exactly, so one step finds the root
    u, v, w, tau = 0.0, 8.0, 2.0, 1.5
    phi = lambda lam: (u * lam + v) / (lam + w)  # noqa: E731
    root = v / tau - w  # solves phi = tau
    p = rational_step(0.0, phi(0) - tau, 3.0, phi(3.0) - tau, math.inf, u - tau)
    assert math.isclose(p, root, rel_tol=1e-12)
    p = rational_step(0.5, phi(0.5) - tau, 1.0, phi(1.0) - tau, 9.0, phi(9.0) - tau)
    assert math.isclose(p, root, rel_tol=1e-12)


def test_search_meets_tolerance_and_stays_bracketed() -> None:
    phi = lambda lam: 10.0 * np.exp(-np.sqrt(lam))  # noqa: E731  (decreasing, not rational)
    res = search_lambda(phi, 0.37, 10.0, 1e-3, 1e-6, 60)
    assert res.converged
    assert abs(res.phi - 0.37) / 0.37 <= 1e-6
    assert res.history[-1] == (res.lam, res.phi)


def test_cap_reports_not_converged() -> None:
    res = search_lambda(lambda lam: 1.0 / (1.0 + lam), 0.5, 1.0, 1e-9, 1e-12, 2)
    assert not res.converged and res.iterations == 2
