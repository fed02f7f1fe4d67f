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
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.optimize import minimize_scalar

from service.core.displacement import tangential_ratio
from service.core.errors import ParameterError
from service.core.geometry import Geometry
from service.core.noise import codimension, discrepancy_tau, estimate_noise, hutchinson_trace
from service.core.params import SmoothingParams
from service.core.system import Deviation

__all__ = ["GCV_PROBES", "AutoTau", "auto_tau", "gcv_lambda"]

GCV_PROBES = 8
EXACT_TRACE = 400


@dataclass(frozen=True)
class AutoTau:
    """The automatic target: ``tau`` (input frame), the noise estimate and how it was chosen."""

    tau: float
    sigma: float
    rule: str


def auto_tau(
    geometry: Geometry,
    params: SmoothingParams,
    fixed: NDArray[np.bool_],
    adjacency: sp.csr_matrix | None = None,
) -> AutoTau:
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
    rho = 0.0
    if params.displacement == "free" and adjacency is not None and r > 0:
        rho = tangential_ratio(geometry.points, adjacency, r)
    tau = discrepancy_tau(est.sigma, w2, r, params.displacement, rho)
    rule = (
        f"automatic: tau = {tau:.6g} from the estimated noise sigma = {est.sigma:.6g} "
        f"(discrepancy principle: {tau / (r * est.sigma**2 * w2):.3g} x {r} x sigma^2 x "
        f"sum omega^2 over {int((~fixed).sum())} free points"
        + (f"; roughness along/across the shape {rho:.3g}" if rho else "")
        + ")"
        if est.sigma > 0
        else "automatic: the input has no measurable noise (sigma = 0)"
    )
    return AutoTau(tau, est.sigma, rule)


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
