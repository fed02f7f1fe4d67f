"""A max-norm bound on the deviation: ``||x_i - p_i|| <= delta`` for every point (report §9).

The report's constraint (3) bounds the *sum* of squared deviations; its conclusion names the
maximum deviation as future work. Here the bound is added to any smoothing target (a given
lambda, a tau, or the automatic tau): raising the weight ``omega_i`` of a point in eq. (4)
pulls that point towards its input position, so

1. solve as usual (lambda given, or found so that ``phi(lambda) = tau`` with the *original*
   weights, eq. 15);
2. for every point with ``||x_i - p_i|| > delta`` multiply ``omega_i^2`` by
   ``(||x_i - p_i|| / delta)^2 (1 + margin)`` (a larger weight makes a smaller deviation);
3. repeat until no point violates the bound, at most ``max_rounds`` times (every round is one
   :meth:`~service.core.system.deviation.Deviation.reweighted` system: same sparsity
   pattern, no new symbolic analysis);
4. if violators remain after the last round, each is moved back radially onto the sphere of
   radius ``delta`` around its input position.

The weights only grow, a point's weight grows geometrically while it violates the bound, and a
point whose weight grew without bound would not move at all, so the rounds shrink the violations;
step 4 makes the guarantee exact whatever happens. The rounds used are reported (see
``benchmarks/quality/README.md`` for the benchmark's). With a tau, phi is searched again with
the original weights after each reweighting, so ``phi = tau`` still holds within the
tolerance unless the bound makes it impossible (``tau`` above ``sum omega_i^2 delta^2``), in
which case the result keeps every point within delta and phi stays below tau (a warning says so).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from service.core.params import TOLERANCE

__all__ = ["BoundResult", "bound_deviation", "point_deviations"]

Array = NDArray[np.float64]
MARGIN = 0.5


class _Deviation(Protocol):
    system: Any

    def deviation(self, lam: float) -> Array: ...

    def reweighted(self, d2: Array) -> _Deviation: ...


@dataclass
class BoundResult:
    """Outcome of :func:`bound_deviation`.

    Attributes
    ----------
    E : ndarray
        Final deviation ``U - U0`` (already clipped where needed).
    lam : float
        Lambda of the last solve.
    phi : float
        ``sum d2 E^2`` with the original weights.
    rounds : int
        Reweighted systems solved after the first solution.
    clipped : int
        Points moved back onto the bound in the final step (0 when the rounds sufficed).
    history : list of (float, float)
        ``(lambda, phi)`` of every solve, original weights.
    warnings : list of str
    """

    E: Array
    lam: float
    phi: float
    rounds: int
    clipped: int
    history: list[tuple[float, float]] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)


def point_deviations(E: Array, group: int) -> Array:
    """``||x_i - p_i||`` per point from ``E`` whose ``group`` consecutive rows are one point."""
    sq = np.sum(E**2, axis=1)
    return np.sqrt(sq.reshape(-1, group).sum(axis=1))


def _phi(d2: Array, E: Array) -> float:
    return float(np.sum(d2[:, None] * E**2))


def _lambda_for_tau(
    phi_of: Callable[[float], float], tau: float, lo: float, hi: float, tolerance: float
) -> float:
    """Root of the decreasing ``phi_of(lambda) = tau`` in ``[lo, hi]``: secant steps on
    ``(log lambda, log phi)`` kept inside a shrinking bracket (Illinois)."""
    a, b = math.log(lo), math.log(hi)
    fa, fb = math.log(phi_of(lo)) - math.log(tau), math.log(phi_of(hi)) - math.log(tau)
    if fa <= 0:
        return lo
    if fb >= 0:
        return hi
    side = 0
    for _ in range(60):
        c = (a * fb - b * fa) / (fb - fa)
        fc = math.log(phi_of(math.exp(c))) - math.log(tau)
        if abs(fc) <= tolerance / 2 or b - a < 1e-12:
            return math.exp(c)
        if fc > 0:
            a, fa = c, fc
            if side == 1:
                fb /= 2
            side = 1
        else:
            b, fb = c, fc
            if side == -1:
                fa /= 2
            side = -1
    return math.exp(c)


def bound_deviation(
    deviation: _Deviation,
    delta: float,
    lam: float,
    *,
    group: int = 1,
    tau: float | None = None,
    bracket: tuple[float, float] | None = None,
    tolerance: float = TOLERANCE,
    max_rounds: int = 30,
) -> BoundResult:
    """Enforce ``||x_i - p_i|| <= delta`` on a solution at ``lam`` (see the module docstring).

    Parameters
    ----------
    deviation : Deviation
        Of the system with the original weights; ``deviation.deviation(lam)`` is ``U - U0``.
    delta : float
        The bound, ``> 0``.
    lam : float
        Lambda of the unbounded solution (given, or found for ``tau``).
    group : int
        Rows of ``U`` per point (``r`` for normal-only displacement in a normal plane).
    tau : float, optional
        Keep ``phi = tau`` (original weights) by a new lambda search after each reweighting.
    bracket : (float, float), optional
        Lambda interval of that search (needed with ``tau``).
    tolerance : float
        Relative tolerance on ``phi`` (``xi``).
    max_rounds : int
        Reweighting rounds before the final radial clip.

    Returns
    -------
    BoundResult
    """
    d2_0 = np.asarray(deviation.system.d2, dtype=np.float64)
    d2 = d2_0.copy()
    history: list[tuple[float, float]] = []
    dev = deviation
    E = dev.deviation(lam)
    history.append((lam, _phi(d2_0, E)))
    rounds = 0
    warnings: list[str] = []
    capacity = float(np.sum(d2_0.reshape(-1, group)[:, 0])) * delta**2
    if tau is not None and tau > (1 - 1e-9) * capacity:
        warnings.append(
            f"max_deviation={delta:.6g} cannot hold with tau={tau:.6g}: tau exceeds "
            "sum omega_i^2 max_deviation^2; every point is kept within max_deviation and phi "
            "stays below tau"
        )
        tau = None
    while rounds < max_rounds:
        norms = point_deviations(E, group)
        over = norms > delta
        if not over.any():
            break
        factor = np.ones_like(norms)
        factor[over] = (norms[over] / delta) ** 2 * (1 + MARGIN)
        d2 = d2 * np.repeat(factor, group)
        dev = deviation.reweighted(d2)
        rounds += 1
        if tau is not None and bracket is not None:

            def phi_of(x: float, dev: _Deviation = dev) -> float:
                value = _phi(d2_0, dev.deviation(x))
                history.append((x, value))
                return value

            lam = _lambda_for_tau(phi_of, tau, bracket[0], bracket[1], tolerance)
        E = dev.deviation(lam)
        history.append((lam, _phi(d2_0, E)))
    norms = point_deviations(E, group)
    over = norms > delta
    clipped = int(over.sum())
    if clipped:
        scale = np.ones_like(norms)
        scale[over] = delta / norms[over]
        E = E * np.repeat(scale, group)[:, None]
        warnings.append(
            f"max_deviation: {clipped} points still exceeded the bound after {rounds} "
            "reweighting rounds and were moved back onto it"
        )
    return BoundResult(E, lam, _phi(d2_0, E), rounds, clipped, history, warnings)
