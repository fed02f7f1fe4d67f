"""Choosing tau without being told: the automatic rule and generalized cross-validation.

* ``tau="auto"`` (also when none of lam, tau, rms is given): estimate the noise level sigma
  (:func:`service.core.noise.estimate_noise`) and take the discrepancy-principle budget
  ``tau = c r sigma^2 sum omega_i^2`` over the points that can move
  (:func:`service.core.noise.discrepancy_tau`); the usual lambda search then meets it.
* ``tau="gcv"``: the lambda minimizing the generalized cross-validation score
  ``V(lambda) = (phi(lambda) / (m c)) / (tr(I - H(lambda)) / m)^2`` of the smoothing system
  (Wahba 1977; Golub, Heath and Wahba 1979), where ``I - H`` maps the data ``U0`` to the
  residual, ``(K^-1 M)^k`` for iterated Tikhonov of order ``k``; its trace comes from
  Hutchinson probes solved with the factorization already made for ``phi(lambda)``
  (:func:`service.core.noise.hutchinson_trace`). ``tau`` is then ``phi`` at that lambda.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from service.core.errors import ParameterError
from service.core.geometry import Geometry
from service.core.noise import codimension, discrepancy_tau, estimate_noise, hutchinson_trace
from service.core.params import SmoothingParams
from service.core.system import Deviation

__all__ = ["GCV_PROBES", "AutoTau", "auto_tau", "gcv_lambda"]

GCV_PROBES = 8


@dataclass(frozen=True)
class AutoTau:
    """The automatic target: ``tau`` (input frame), the noise estimate and how it was chosen."""

    tau: float
    sigma: float
    rule: str


def auto_tau(geometry: Geometry, params: SmoothingParams, fixed: NDArray[np.bool_]) -> AutoTau:
    """``tau`` from the estimated noise (discrepancy principle, calibrated factor).

    Raises
    ------
    ParameterError
        When the noise cannot be estimated (too few points, degenerate input): give tau, rms
        or lam.
    """
    est = estimate_noise(geometry)
    if est is None:
        raise ParameterError(
            "the noise level of this input cannot be estimated (too few or degenerate points): "
            "give tau, rms or lam",
            field="params.tau",
        )
    r = codimension(geometry)
    w2 = float(np.sum(geometry.omega()[~fixed] ** 2))
    tau = discrepancy_tau(est.sigma, w2, r, params.displacement)
    rule = (
        f"automatic: tau = {tau:.6g} from the estimated noise sigma = {est.sigma:.6g} "
        f"(discrepancy principle, tau = {tau / (r * est.sigma**2 * w2):g} x {r} x sigma^2 x "
        f"sum omega^2 over {int((~fixed).sum())} free points)"
        if est.sigma > 0
        else "automatic: the input has no measurable noise (sigma = 0)"
    )
    return AutoTau(tau, est.sigma, rule)


def _residual_trace(dev: Deviation, lam: float, probes: int) -> float:
    """``tr((K^-1 M)^k)`` by Hutchinson probes (k solves of ``probes`` columns)."""
    solver = dev.solver

    def apply(Z: NDArray[np.float64]) -> NDArray[np.float64]:
        Y = Z
        for _ in range(dev.order):
            Y = solver.solve(lam, solver.matvec(Y))
        return Y

    return hutchinson_trace(apply, dev.system.size, probes)


def gcv_lambda(
    dev: Deviation, lo: float, hi: float, start: float, probes: int = GCV_PROBES
) -> float:
    """Minimizer of the GCV score over ``[lo, hi]`` (internal frame), from ``start``.

    A scan of ``start * 10^j``, ``j = -3 .. 3``, then golden-section refinement in log lambda
    (12 evaluations in all, each one factorization and ``k (probes + 1)`` solves).
    """
    m, c = dev.system.U0.shape
    scores: dict[float, float] = {}

    def score(x: float) -> float:
        lam = min(max(math.exp(x), lo), hi)
        if lam not in scores:
            phi = dev(lam)
            tr = _residual_trace(dev, lam, probes)
            scores[lam] = (phi / (m * c)) / (tr / m) ** 2 if tr > 0 else math.inf
        return scores[lam]

    grid = [math.log(start) + j * math.log(10.0) for j in range(-3, 4)]
    vals = [score(x) for x in grid]
    i = int(np.argmin(vals))
    a, b = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    g = (math.sqrt(5) - 1) / 2
    x1, x2 = b - g * (b - a), a + g * (b - a)
    f1, f2 = score(x1), score(x2)
    for _ in range(3):
        if f1 < f2:
            b, x2, f2 = x2, x1, f1
            x1 = b - g * (b - a)
            f1 = score(x1)
        else:
            a, x1, f1 = x1, x2, f2
            x2 = a + g * (b - a)
            f2 = score(x2)
    best = min(scores, key=lambda k: scores[k])
    if not math.isfinite(scores[best]):
        raise ParameterError(
            "generalized cross-validation found no finite score", field="params.tau"
        )
    return best
