"""Finding lambda so that the deviation ``phi(lambda)`` equals the smoothing factor ``tau``.

Two searches, selectable by name (``SmoothingParams.search``):

* ``"newton"`` (the default): a lambda estimate with no factorization from the Gauss quadrature
  of a few Lanczos steps (:mod:`service.core.linalg.krylov`), then Newton's method on
  ``h(lambda) = phi^(-1/(2k)) - tau^(-1/(2k))`` (Reinsch 1967; More and Sorensen 1983) with
  ``phi'`` from one extra solve. ``h`` is concave and increasing
  (:mod:`service.core.system.deviation`),
  so from the left Newton never overshoots the root, and a bracket ``lo < lambda* <= hi`` with
  ``hi = ||c|| / sqrt(tau)`` (one product) makes every step safe: a step leaving the bracket is
  replaced by a geometric bisection. The solver reuses its factorization at nearby lambdas,
  so the common case costs one numeric factorization.
* ``"rational"``: the report's rational interpolation (below), kept to reproduce its behaviour.

``phi(lambda) = ||D(X(lambda) - P)||_F^2`` (eq. 15) is convex and strictly decreasing, from
``phi(0) = ||D(P - P_bar)||_F^2`` (eq. 14) to ``phi(inf) = 0``. Section 6.3 of the report finds
``phi(lambda*) = tau`` by rational interpolation as in Dierckx's FITPACK (``fprati``): through
three points ``(lambda_1, f_1), (lambda_2, f_2), (lambda_3, f_3)`` with ``f = phi - tau``, starting
from ``lambda_1 = 0``, ``lambda_3 = inf`` and ``lambda_2 = ||L^T L||_F / ||D^2||_F``, fit
``R(lambda) = (u lambda + v) / (lambda + w)`` and take its root as the next lambda; the bracket
``f_1 > 0 > f_3`` is kept. A step that leaves the bracket is replaced by a (geometric) bisection,
so the search always converges.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from service.core.linalg.krylov import Quadrature, lanczos
from service.core.params import MAX_ITERATIONS, TOLERANCE

__all__ = [
    "LambdaSearch",
    "estimate_lambda",
    "initial_lambda",
    "newton_search",
    "rational_step",
    "search_lambda",
    "unresolved_below",
]


@dataclass
class LambdaSearch:
    """Outcome of the lambda search.

    Attributes
    ----------
    lam, phi : float
        The last lambda tried and its deviation.
    converged : bool
        ``|phi - tau| / tau <= tolerance``.
    history : list of (float, float)
        Every ``(lambda, phi)`` evaluated, in order.
    """

    lam: float
    phi: float
    converged: bool
    history: list[tuple[float, float]] = field(default_factory=list)

    @property
    def iterations(self) -> int:
        return len(self.history)


def initial_lambda(m_fro: float, d2_fro: float) -> float:
    """``lambda_2 = ||L^T L||_F / ||D^2||_F`` (report section 6.3, after [14])."""
    if m_fro > 0 and d2_fro > 0:
        return m_fro / d2_fro
    return 1.0


def rational_step(p1: float, f1: float, p2: float, f2: float, p3: float, f3: float) -> float:
    """Root of the rational ``R(p) = (u p + v) / (p + w)`` through three points.

    ``p3 = inf`` is allowed (then ``R(inf) = f3``). Same formulas as FITPACK's ``fprati``.

    Parameters
    ----------
    p1, f1, p2, f2, p3, f3 : float
        Abscissae ``p1 < p2 < p3`` and values ``f_i = phi(p_i) - tau``.

    Returns
    -------
    float
        The next lambda (may be outside the bracket or not finite; the caller checks).
    """
    if math.isinf(p3):
        den = (f1 - f2) * f3
        return (p1 * (f1 - f3) * f2 - p2 * (f2 - f3) * f1) / den if den != 0 else math.nan
    h1 = f1 * (f2 - f3)
    h2 = f2 * (f3 - f1)
    h3 = f3 * (f1 - f2)
    den = p1 * h1 + p2 * h2 + p3 * h3
    return -(p1 * p2 * h3 + p2 * p3 * h1 + p3 * p1 * h2) / den if den != 0 else math.nan


def _bisect(p1: float, p3: float, p2: float) -> float:
    if math.isinf(p3):
        return max(p2, p1) * 10.0
    if p1 <= 0.0:
        return min(p2, p3) / 10.0
    return math.sqrt(p1 * p3)


def search_lambda(
    phi_of: Callable[[float], float],
    tau: float,
    phi0: float,
    lam0: float,
    tolerance: float,
    max_iterations: int,
) -> LambdaSearch:
    """Find lambda with ``|phi(lambda) - tau| / tau <= tolerance`` (report section 6.3).

    Parameters
    ----------
    phi_of : callable
        ``phi_of(lam)`` solves eq. (4) at ``lam`` and returns ``phi(lam)`` (eq. 15).
    tau : float
        Target, ``0 < tau < phi0``.
    phi0 : float
        ``phi(0)``.
    lam0 : float
        First lambda to try (``lambda_2``).
    tolerance : float
        ``xi``.
    max_iterations : int
        Cap on evaluations of ``phi_of``.

    Returns
    -------
    LambdaSearch
        The best lambda found; ``converged`` is false when the cap was hit.
    """
    p1, f1 = 0.0, phi0 - tau
    p3, f3 = math.inf, -tau
    p2 = lam0
    history: list[tuple[float, float]] = []
    best: tuple[float, float] | None = None
    for _ in range(max_iterations):
        phi2 = phi_of(p2)
        history.append((p2, phi2))
        f2 = phi2 - tau
        if best is None or abs(f2) < abs(best[1] - tau):
            best = (p2, phi2)
        if abs(f2) <= tolerance * tau:
            return LambdaSearch(p2, phi2, True, history)
        p = rational_step(p1, f1, p2, f2, p3, f3)
        # keep the bracket f1 > 0 > f3 around the root
        if f2 < 0:
            p3, f3 = p2, f2
        else:
            p1, f1 = p2, f2
        if not (math.isfinite(p) and p1 < p < p3) or p in (p1, p3):
            p = _bisect(p1, p3, p2)
        if p1 > 0 and not math.isinf(p3) and p3 - p1 <= 1e-14 * p3:
            break  # bracket collapsed: phi is flat here, tau cannot be met more closely
        p2 = p
    assert best is not None
    lam, phi = best
    return LambdaSearch(lam, phi, False, history)


def estimate_lambda(
    apply_mt: Callable[[NDArray[np.float64]], NDArray[np.float64]],
    c: NDArray[np.float64],
    tau: float,
    lo: float,
    hi: float,
    *,
    order: int = 1,
    max_steps: int = 60,
    ratio: float = 1.01,
) -> tuple[float, float, float, int]:
    """lambda estimate from Gauss and Gauss-Radau quadrature models (no factorization).

    For ``k = 1`` the root of the Gauss model is a lower bound of ``lambda*`` and the root of
    the Radau model an upper bound (in exact arithmetic,
    :func:`~service.core.linalg.krylov.lanczos`);
    the steps stop when they agree within ``ratio`` or after ``max_steps``. For ``k > 1``,
    ``phi_k(lambda) <= phi_1(k lambda)`` termwise (Bernoulli's inequality), so ``lambda*_k``
    lies below ``upper_1 / k``; the estimate is the root of the order-``k`` Gauss model below it.

    Parameters
    ----------
    apply_mt : callable
        Products with ``M_t = D^-1 M D^-1``.
    c : ndarray, shape (m, s)
        ``D^-1 r``.
    tau, lo, hi : float
        Target and the search's bracket.
    order : int
        Iterated Tikhonov order.
    max_steps : int
        Lanczos steps at most.
    ratio : float
        Target ratio of the upper to the lower bound.

    Returns
    -------
    lam : float
        The estimate.
    lower, upper : float
        Bounds for order 1 (``upper / k`` bounds ``lambda*_k`` from above).
    steps : int
        Products with ``M_t``.
    """
    bounds = [lo, hi, lo]

    def stop(gauss: Quadrature, radau: Quadrature) -> bool:
        bounds[0] = gauss.root(tau, lo, hi, order=1)
        bounds[1] = radau.root(tau, lo, hi, order=1)
        if order > 1:
            bounds[2] = gauss.root(tau, lo, hi)
        return lo < bounds[0] and bounds[1] <= ratio * bounds[0]

    # the models cost more than a step at small n: look at them every third step after four
    _, _, steps = lanczos(apply_mt, c, max_steps, stop, order, every=3)
    lower, upper, root_k = bounds
    if order > 1:
        cap = upper / order
        return (min(root_k, cap) if root_k > lo else cap), lower, upper, steps
    # close bounds: their geometric mean; else the upper bound, from where the shift-invert
    # model of the factorization made there converges fastest (krylov.ShiftInvert)
    lam = math.sqrt(lower * upper) if upper <= 1.5 * lower else upper
    return lam, lower, upper, steps


#: Relative rise of ``phi`` with ``lambda`` taken as rounding, not as a resolved ``phi``.
MONOTONE_RTOL = 1e-6


def _monotone(history: list[tuple[float, float]]) -> bool:
    """Whether the last ``phi`` keeps ``phi(lambda)`` non-increasing (eq. 15: ``phi' < 0``)
    against every earlier evaluation, within :data:`MONOTONE_RTOL`. It does not at lambdas so
    small that the solve's rounding swamps ``phi`` (an 800K-point curve at ``lambda ~ 5e-13``:
    0.69, 0.34, 5.78, 0.10 at falling lambdas; the search ran its 50 evaluations, ~6 CPU
    minutes): then no evaluation can bring the root closer."""
    lam, phi = history[-1]
    for other, value in history[:-1]:
        if (other < lam and value < phi * (1 - MONOTONE_RTOL)) or (
            other > lam and value > phi * (1 + MONOTONE_RTOL)
        ):
            return False
    return True


def unresolved_below(history: list[tuple[float, float]]) -> float | None:
    """The largest lambda of ``history`` at which ``phi`` rose with lambda (see
    :func:`_monotone`), ``None`` when ``phi`` was non-increasing throughout."""
    worst = None
    for i in range(1, len(history) + 1):
        if not _monotone(history[:i]):
            lam = max(history[i - 1][0], *(other for other, _ in history[: i - 1]))
            worst = lam if worst is None else max(worst, lam)
    return worst


def newton_search(
    dev: Callable[[float], float],
    derivative: Callable[[float], float],
    tau: float,
    lam0: float,
    lo: float,
    hi: float,
    *,
    order: int = 1,
    tolerance: float = TOLERANCE,
    max_iterations: int = MAX_ITERATIONS,
    propose: Callable[[float, float, float, float], float | None] | None = None,
    below: Callable[[], None] | None = None,
) -> LambdaSearch:
    """Safeguarded Newton on ``h = phi^(-1/(2k)) - tau^(-1/(2k))`` inside ``[lo, hi]``.

    ``propose(lam, tau, lo, hi)``, when given and not ``None``, replaces Newton's step (e.g.
    the root of a shift-invert model built with the factorization just made); the same
    safeguard applies to it. ``below()`` is called once when Newton's tangent from a point with
    ``phi < tau`` falls below ``lo`` (``tau`` may exceed ``phi(0)``; it raises if so).

    Parameters
    ----------
    dev : callable
        ``phi(lambda)`` (eq. 15).
    derivative : callable
        ``phi'(lambda)``.
    tau : float
    lam0 : float
        First lambda (e.g. :func:`estimate_lambda`).
    lo, hi : float
        Bracket: ``phi(hi) <= tau``; ``lo`` is the smallest lambda allowed.
    order : int
        ``k``.
    tolerance, max_iterations
        ``xi`` and the cap on evaluations of ``phi``.

    Returns
    -------
    LambdaSearch
        ``converged`` is false when the cap was hit or the bracket collapsed.
    """
    e = -1.0 / (2 * order)
    target = tau**e
    history: list[tuple[float, float]] = []
    lam = min(max(lam0, lo), hi)
    best: tuple[float, float] | None = None
    for _ in range(max_iterations):
        phi = dev(lam)
        history.append((lam, phi))
        if best is None or abs(phi - tau) < abs(best[1] - tau):
            best = (lam, phi)
        if abs(phi - tau) <= tolerance * tau:
            return LambdaSearch(lam, phi, True, history)
        if not _monotone(history):
            break  # phi unresolved at these lambdas (rounding): no closer root to find
        if phi > tau:
            lo = lam
        else:
            hi = lam
        if hi - lo <= 1e-14 * hi:
            break  # bracket collapsed: tau cannot be met more closely
        new = propose(lam, tau, lo, hi) if propose is not None else None
        if new is None or new in (lo, hi):
            try:  # phi near the underflow limit (tau ~ 1e-300): the power overflows
                slope = e * phi ** (e - 1.0) * derivative(lam) if phi > 0 else 0.0
                new = lam - (phi**e - target) / slope if slope > 0 else math.nan
            except (OverflowError, ZeroDivisionError):
                new = math.nan  # the safeguard below takes a geometric bisection step
            if below is not None and phi < tau and not new > lo:
                below()
                below = None
        if not (math.isfinite(new) and lo < new < hi):
            new = math.sqrt(lo * hi) if lo > 0 else hi * 1e-3
        if new == lam:
            break
        lam = new
    assert best is not None
    return LambdaSearch(best[0], best[1], False, history)
