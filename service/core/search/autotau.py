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
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from service.core.errors import ParameterError
from service.core.geometry import Geometry
from service.core.linalg.krylov import Quadrature, _models, log_bisect
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


#: The window of tau around the discrepancy estimate where the knee is looked for.
KNEE_WINDOW = (0.4, 2.0)
KNEE_STEPS = (40, 400)
KNEE_CHECKPOINTS = (40, 60, 90, 135, 200, 300)
#: Checkpoints without a knee before giving up: a sharp plateau (40K-vertex sphere and torus,
#: anisotropic 0.5 h) is flat up to the window's edge in the 40- and 60-step models and only
#: resolved at 90: giving up after two left the discrepancy estimate (distance to the surface
#: 0.20 / 0.22 against the oracle's 0.067 / 0.075); after four, the knee gives 0.068 / 0.076.
KNEE_GIVE_UP = 3
#: Up to this many unknowns phi(lambda) is evaluated from the exact spectrum of ``M_t`` (dense
#: eigendecomposition, ~0.1 s): the Lanczos models of a curve's clustered spectrum need more
#: steps than the unknowns allow (circle 2-D, 0.25 h: vertex error 0.73 with them, 0.20 exact).
DENSE_KNEE = 1200


def _lanczos_checkpoints(
    apply: Callable[[Array], Array], c: Array, checkpoints: list[int], order: int
) -> Iterator[tuple[Quadrature, Quadrature]]:
    """Lanczos on ``apply`` from the columns of ``c``; the Gauss and Gauss-Radau models of
    ``phi`` at the given step counts only (building them costs O(j^3) per column, so not after
    every step as :func:`service.core.linalg.krylov.lanczos` does for its short runs)."""
    beta0 = np.linalg.norm(c, axis=0)
    live = beta0 > 0
    beta0 = beta0[live]
    V = c[:, live] / beta0
    V_prev = np.zeros_like(V)
    b_prev = np.zeros(V.shape[1])
    alphas: list[Array] = []
    betas: list[Array] = []
    steps = checkpoints[-1]
    for j in range(1, steps + 1):
        W = apply(V) - V_prev * b_prev
        a = np.einsum("ij,ij->j", V, W)
        W -= V * a
        b = np.linalg.norm(W, axis=0)
        alphas.append(a)
        betas.append(b)
        broke = not np.all(b > 1e-14 * np.abs(a).max())
        if j in checkpoints or broke:
            yield _models(alphas, betas, beta0, order)
        if broke:
            return
        V_prev, V, b_prev = V, W / b, b


def _flattest(lams: Array, phis: Array) -> int | None:
    """Index of the flattest point of ``log phi`` against ``log lambda`` (interior only)."""
    slope = np.gradient(np.log(np.maximum(phis, 1e-300)), np.log(lams))
    i = int(np.argmax(slope))
    return i if 2 <= i <= lams.size - 3 else None


def _dense_knee(dev: Deviation, lo_tau: float, hi_tau: float) -> float | None:
    """The knee from the exact ``phi(lambda) = sum_i c_i^2 mu_i^(2k-2) / (mu_i + lambda)^(2k)``
    (generalized eigenpairs of ``(M, D^2)``, small systems)."""
    s = dev.system
    d = np.sqrt(s.d2)[:, None]
    Mt = dev.solver.matvec(np.eye(s.size) / d) / d
    mu, V = np.linalg.eigh(0.5 * (Mt + Mt.T))
    mu = np.maximum(mu, 0.0)
    c2 = np.sum((V.T @ (s.r / d)) ** 2, axis=1)
    k = dev.order

    def phi(lam: float) -> float:
        return float(np.sum(c2 * mu ** (2 * k - 2) / (mu + lam) ** (2 * k)))

    lo, hi = dev.floor, max(s.lambda_ceiling(lo_tau), dev.floor)
    lam_hi = log_bisect(phi, lo_tau, lo, hi)
    lam_lo = log_bisect(phi, hi_tau, lo, hi)
    if not lam_lo < lam_hi:
        return None
    grid = np.geomspace(lam_lo, lam_hi, 400)
    phis = np.array([phi(x) for x in grid])
    i = _flattest(grid, phis)
    return None if i is None else float(phis[i])


def knee_tau(dev: Deviation, tau0: float) -> float | None:
    """The knee of ``phi(lambda)`` near ``tau0`` (internal frame), or ``None``.

    ``log phi`` against ``log lambda`` rises steeply while the noise is being removed and then
    flattens where only the noise is gone and the shape itself is not yet smoothed; the
    flattest point in ``KNEE_WINDOW x tau0`` (the estimated noise energy) is where the error
    against the clean shape is smallest on the quality benchmark's smooth shapes (within 4 %
    of the oracle). ``phi`` comes from the Gauss and Gauss-Radau quadrature models of Lanczos
    on ``M_t`` (products with ``M`` only, no factorization, as in
    :func:`service.core.linalg.krylov.lanczos`), checked after 40, 60, 90, ... steps until the knee
    moves less than 1 % (at most ``KNEE_STEPS[1]`` steps, or half the unknowns). ``None``
    when the window holds no interior knee (then the discrepancy estimate is used).
    """
    s = dev.system
    inv_d = 1.0 / np.sqrt(s.d2)[:, None]
    lo_tau, hi_tau = KNEE_WINDOW[0] * tau0, KNEE_WINDOW[1] * tau0

    if s.size <= DENSE_KNEE:
        return _dense_knee(dev, lo_tau, hi_tau)

    def knee(gauss: Quadrature, radau: Quadrature) -> float | None:
        lo, hi = dev.floor, max(s.lambda_ceiling(lo_tau), dev.floor)
        lam_hi, lam_lo = gauss.root(lo_tau, lo, hi), gauss.root(hi_tau, lo, hi)
        if not lam_lo < lam_hi:
            return None
        grid = np.geomspace(lam_lo, lam_hi, 240)
        phi = np.array([math.sqrt(max(gauss.phi(x), 1e-300) * max(radau.phi(x), 1e-300))
                        for x in grid])
        i = _flattest(grid, phi)
        return None if i is None else float(grid[i])

    cap = max(KNEE_STEPS[0], min(KNEE_STEPS[1], s.size // 2))
    checkpoints = [j for j in KNEE_CHECKPOINTS if j < cap] + [cap]
    lam: float | None = None
    previous: float | None = None
    for checks, (gauss, radau) in enumerate(_lanczos_checkpoints(
        lambda V: inv_d * dev.solver.matvec(inv_d * V), inv_d * s.r, checkpoints, dev.order
    )):
        lam = knee(gauss, radau)
        if lam is None and checks >= KNEE_GIVE_UP and previous is None:
            break  # no knee after KNEE_GIVE_UP + 1 checkpoints: there is none to find
        if lam is not None and previous is not None and abs(math.log(lam / previous)) < 0.01:
            break
        previous = lam
    if lam is None:
        return None
    return math.sqrt(gauss.phi(lam) * radau.phi(lam))
