"""One budget over all tiles: the coordinator's root of ``sum_t phi_t(lambda) = tau``.

``phi(lambda) = ||D(X - P)||^2`` (eq. 15) is a sum over points, so the untiled phi is the sum of
the cores' shares ``phi_t``. Each tile's round 0 (:func:`~service.core.tiles.solve.probe_tile`)
leaves a model of its share: the ``(lambda, phi)`` pairs of its own search, interpolated
linearly in ``(ln lambda, ln phi)`` (phi is a smooth decreasing function, close to a power of
lambda over a decade), times the core's fraction of the tile's phi. The coordinator

1. solves ``sum_t m_t(lambda) = tau`` on the models (bisection in ``ln lambda``; no tile work);
2. asks every tile for its exact ``phi_t`` at that lambda (one round: one numeric
   factorization and ``k`` solves per tile);
3. corrects: the models rescaled by the measured ratio for the second candidate, then the
   secant on ``(ln lambda, ln S)`` through the last two exact sums, kept inside the bracket
   the exact sums have established (geometric bisection when the secant leaves it), until
   ``|S - tau| / tau <= xi``.

Only scalars travel; the coordinator's memory is ``O(tiles x history)``, independent of n.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["BudgetResult", "PhiModel", "model_root", "solve_budget"]

#: Log-log slope assumed beyond a model's samples (phi ~ lambda^-1 mid-range).
DEFAULT_SLOPE = -1.0


@dataclass(frozen=True)
class PhiModel:
    """A tile's model ``m(lambda) = ratio * exp(interp(ln lambda))`` of its phi share."""

    lams: tuple[float, ...]
    phis: tuple[float, ...]
    ratio: float

    @classmethod
    def of(cls, history: Sequence[tuple[float, float]], ratio: float) -> PhiModel:
        """From a search history (pairs with positive numbers only, sorted by lambda)."""
        pairs = sorted({(lam, phi) for lam, phi in history if lam > 0 and phi > 0})
        return cls(tuple(p[0] for p in pairs), tuple(p[1] for p in pairs), ratio)

    def __call__(self, lam: float) -> float:
        if not self.lams:
            return 0.0
        x = np.log(self.lams)
        y = np.log(self.phis)
        t = math.log(lam)
        if len(x) == 1 or t < x[0] or t > x[-1]:
            end = 0 if len(x) == 1 or t < x[0] else -1
            other = 1 if end == 0 else -2
            slope = DEFAULT_SLOPE
            if len(x) > 1 and x[other] != x[end]:
                slope = min((y[other] - y[end]) / (x[other] - x[end]), -1e-3)
            return float(self.ratio * math.exp(y[end] + slope * (t - x[end])))
        return float(self.ratio * math.exp(np.interp(t, x, y)))


def model_root(
    model: Callable[[float], float], tau: float, lo: float, hi: float, steps: int = 100
) -> float:
    """Root of the decreasing ``model(lambda) = tau`` by bisection in ``ln lambda`` on
    ``[lo, hi]`` (the bracket widened by decades until it holds the root)."""
    for _ in range(60):
        if model(lo) >= tau:
            break
        lo /= 10
    for _ in range(60):
        if model(hi) <= tau:
            break
        hi *= 10
    a, b = math.log(lo), math.log(hi)
    for _ in range(steps):
        mid = 0.5 * (a + b)
        if model(math.exp(mid)) > tau:
            a = mid
        else:
            b = mid
        if b - a < 1e-12:
            break
    return math.exp(0.5 * (a + b))


@dataclass(frozen=True)
class BudgetResult:
    """The coordinator's answer: lambda, the exact sum there and every round's ``(lam, S)``."""

    lam: float
    phi: float
    shares: list[float]
    rounds: int
    history: list[tuple[float, float]]
    converged: bool


def solve_budget(
    tau: float,
    models: Sequence[PhiModel],
    evaluate: Callable[[float], list[float]],
    tolerance: float = 1e-3,
    max_rounds: int = 8,
) -> BudgetResult:
    """``lambda`` with ``|sum_t phi_t(lambda) - tau| / tau <= tolerance``.

    Parameters
    ----------
    tau : float
        The global budget (input frame).
    models : sequence of PhiModel
        Round 0's models of the tiles' shares.
    evaluate : callable
        ``lambda -> [phi_t]``: one round of exact per-tile solves.
    tolerance : float
        ``xi``.
    max_rounds : int
        Rounds of exact solves at most.
    """
    lams = [lam for m in models for lam in m.lams] or [1.0]

    def total(lam: float) -> float:
        return sum(m(lam) for m in models)

    lam = model_root(total, tau, min(lams), max(lams))
    below: tuple[float, float] | None = None  # (lam, S) with S > tau: lambda too small
    above: tuple[float, float] | None = None
    history: list[tuple[float, float]] = []
    rounds: list[list[float]] = []
    for rnd in range(1, max_rounds + 1):
        shares = evaluate(lam)
        S = float(sum(shares))
        history.append((lam, S))
        rounds.append(shares)
        if abs(S - tau) <= tolerance * tau:
            return BudgetResult(lam, S, shares, rnd, history, True)
        if tau < S:
            below = (lam, S) if below is None or lam > below[0] else below
        else:
            above = (lam, S) if above is None or lam < above[0] else above
        lam = _next(lam, S, tau, total, history, below, above)
    best = min(range(len(history)), key=lambda i: abs(history[i][1] - tau))
    lam, S = history[best]
    return BudgetResult(lam, S, rounds[best], max_rounds, history, False)


def _next(
    lam: float,
    S: float,
    tau: float,
    total: Callable[[float], float],
    history: list[tuple[float, float]],
    below: tuple[float, float] | None,
    above: tuple[float, float] | None,
) -> float:
    """The next candidate: rescaled model (second round), then the log-log secant,
    safeguarded by the bracket of exact sums."""
    if len(history) == 1:
        scale = S / max(total(lam), 1e-300)
        cand = model_root(lambda x: scale * total(x), tau, lam / 10, lam * 10)
    else:
        (l1, s1), (l2, s2) = history[-2], history[-1]
        dx, dy = math.log(l2) - math.log(l1), math.log(s2) - math.log(s1)
        slope = dy / dx if dx != 0 and dy != 0 else -1.0
        slope = min(slope, -1e-3)
        cand = math.exp(math.log(l2) + (math.log(tau) - math.log(s2)) / slope)
    if below is not None and above is not None:
        lo, hi = below[0], above[0]
        if not lo < cand < hi:
            cand = math.sqrt(lo * hi)
    return cand
