"""Choosing tau without being told: the automatic rule and generalized cross-validation.

* ``tau="auto"`` (also when none of lam, tau, rms is given): estimate the noise level sigma
  (:func:`service.core.noise.estimate.estimate_noise`) and take the discrepancy-principle budget
  ``tau = c r sigma^2 sum omega_i^2`` over the points that can move
  (:func:`discrepancy_tau`); the usual lambda search then meets it.
* ``tau="gcv"``: the lambda minimizing the generalized cross-validation score
  ``V(lambda) = (phi(lambda) / (m c)) / (tr(I - H(lambda)) / m)^2`` of the smoothing system
  (Wahba 1977; Golub, Heath and Wahba 1979), where ``I - H`` maps the data ``U0`` to the
  residual, ``(K^-1 M)^k`` for iterated Tikhonov of order ``k``; its trace comes from
  Hutchinson probes solved with the factorization already made for ``phi(lambda)``
  (:func:`service.core.noise.estimate.hutchinson_trace`). ``tau`` is then ``phi`` at that lambda.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from service.core.errors import ParameterError
from service.core.geometry import Geometry
from service.core.noise.estimate import (
    codimension,
    estimate_noise,
    hutchinson_trace,
)
from service.core.params import SmoothingParams
from service.core.system.deviation import Deviation
from service.core.system.displacement import tangential_ratio

__all__ = [
    "GCV_PROBES",
    "TANGENTIAL_SHARE",
    "TAU_FACTOR",
    "AutoTau",
    "auto_tau",
    "discrepancy_tau",
    "gcv_lambda",
]

GCV_PROBES = 8
Array = NDArray[np.float64]
EXACT_TRACE = 400


#: ``c`` of the discrepancy rule ``tau = c * r * sigma^2 * sum omega_i^2 * (1 + alpha rho)``
#: (``r`` normal directions per point), per displacement mode, and ``alpha`` (free
#: displacement only); calibrated on the quality benchmark (``benchmarks/quality/README.md``).
TAU_FACTOR: dict[str, float] = {"free": 0.9, "normal": 1.0}
TANGENTIAL_SHARE = 1.0


def discrepancy_tau(
    sigma: float, weight_sum: float, codim: int, displacement: str, rho: float = 0.0
) -> float:
    """``tau = c r sigma^2 sum omega_i^2 (1 + alpha rho)``: the noise energy smoothing removes.

    With noise of standard deviation ``sigma`` across the shape, a smoothing that removes the
    noise and nothing else moves each point by about ``sigma`` per normal direction; part of
    the noise stays in the smooth result (the degrees of freedom the filter keeps), which the
    calibrated factor ``c`` (:data:`TAU_FACTOR`) accounts for. Free displacement also moves
    points along the shape, in proportion to the roughness along it: ``rho`` is its ratio to
    the roughness across (:func:`service.core.system.displacement.tangential_ratio`) and ``alpha``
    (:data:`TANGENTIAL_SHARE`) the calibrated share of it worth spending.
    """
    extra = 1.0 + TANGENTIAL_SHARE * rho if displacement == "free" else 1.0
    return TAU_FACTOR[displacement] * codim * sigma**2 * weight_sum * extra


@dataclass(frozen=True)
class AutoTau:
    """The automatic target: ``tau`` (input frame), the noise estimate and how it was chosen."""

    tau: float
    sigma: float
    rule: str
    #: The tau the local roughness would give if it were all noise (GCV's starting point).
    rough_tau: float = 0.0


def auto_tau(
    geometry: Geometry,
    params: SmoothingParams,
    fixed: NDArray[np.bool_],
    adjacency: sp.csr_matrix | None = None,
    tau_scale: Array | None = None,
) -> AutoTau:
    """``tau`` from the estimated noise (discrepancy principle, calibrated factor).

    ``tau = 0`` (the run returns its input unchanged, ``rule`` says why) when there is nothing
    to remove: no noise found (:func:`~service.core.noise.estimate.estimate_noise`: exactly
    smooth, or residuals that grow with the neighbourhood like the shape's own detail), no
    estimate possible (too few or degenerate points), or no point free to move. ``tau_scale``:
    ``sigma_i / sigma`` per point when the data weights follow the noise
    (:mod:`~service.core.noise.robust`): the budget sums ``(omega_i sigma_i / sigma)^2``.
    """
    est = estimate_noise(geometry)
    if est is None:
        return AutoTau(0.0, 0.0, "automatic: the noise level of this input cannot be estimated "
                       "(too few or degenerate points): returned unchanged; give tau, rms or lam "
                       "to smooth it")
    r = codimension(geometry)
    omega = geometry.omega() if tau_scale is None else geometry.omega() * tau_scale
    w2 = float(np.sum(omega[~fixed] ** 2))  # sigma_i-scaled with noise weights (issue 21)
    if not est.noise_found:
        rough = discrepancy_tau(est.roughness, w2, r, params.displacement)
        return AutoTau(0.0, 0.0, f"automatic: {est.describe()}: returned unchanged; give tau, "
                       "rms or lam to smooth it anyway", rough)
    if r == 0 or w2 == 0:
        return AutoTau(0.0, est.sigma, f"automatic: {est.describe()}, but no point is free to "
                       "move: returned unchanged")
    rho = 0.0
    if params.displacement == "free" and adjacency is not None and est.track is None:
        rho = tangential_ratio(geometry.points, adjacency, r)  # a track: reciprocal weights
    tau = discrepancy_tau(est.sigma, w2, r, params.displacement, rho)
    rule = (
        f"automatic: {est.describe()}; tau = {tau:.6g} "
        f"(discrepancy principle: {tau / (r * est.sigma**2 * w2):.3g} x {r} x sigma^2 x "
        f"sum omega^2 over {int((~fixed).sum())} free points"
        + (f"; roughness along/across the shape {rho:.3g}" if rho else "")
        + ")"
    )
    return AutoTau(tau, est.sigma, rule, tau)


def _residual_trace(dev: Deviation, lam: float, probes: int) -> float:
    """``tr((K^-1 M)^k)``: exact for up to :data:`EXACT_TRACE` unknowns (the identity's
    columns as probes), else by Hutchinson probes (``k`` solves of ``probes`` columns, more
    probes on smaller systems so that the relative error stays near 1 %)."""
    solver = dev.solver
    m = dev.system.size

    def apply(Z: NDArray[np.float64]) -> NDArray[np.float64]:
        Y = Z
        for _ in range(dev.order):
            Y = solver.solve(lam, solver.matvec(Y))
        return Y

    if m <= EXACT_TRACE:
        return float(np.trace(apply(np.eye(m))))
    return hutchinson_trace(apply, m, max(probes, min(64, 20000 // m)))


def gcv_lambda(
    dev: Deviation, lo: float, hi: float, start: float, probes: int = GCV_PROBES
) -> float:
    """Minimizer of the GCV score over ``[lo, hi]`` (internal frame), from ``start``.

    A scan of ``start * 10^(j/2)``, ``j = -4 .. 4``, then Brent's method in log lambda on the
    bracket around the best scanned value (to 0.02 decades): about 15 evaluations, each one
    factorization and ``k (probes + 1)`` solves.
    """
    m, c = dev.system.U0.shape
    scores: dict[float, float] = {}

    def score(x: float) -> float:
        lam = min(max(math.exp(x), lo), hi)
        if lam not in scores:
            phi = dev(lam)
            tr = _residual_trace(dev, lam, probes)
            scores[lam] = math.log((phi / (m * c)) / (tr / m) ** 2) if tr > 0 else math.inf
        return scores[lam]

    step = 0.5 * math.log(10.0)
    grid = [math.log(start) + j * step for j in range(-4, 5)]
    vals = [score(x) for x in grid]
    i = int(np.argmin(vals))
    if 0 < i < len(grid) - 1:
        from scipy.optimize import minimize_scalar  # GCV only: not loaded by other runs

        minimize_scalar(
            score, bracket=(grid[i - 1], grid[i], grid[i + 1]), method="brent",
            options={"xtol": 1e-2},
        )
    best = min(scores, key=lambda k: scores[k])
    if not math.isfinite(scores[best]):
        raise ParameterError(
            "generalized cross-validation found no finite score", field="params.tau"
        )
    return best
