"""The automatic lambda (issue 37): the minimiser of the unbiased predictive risk with the
larger of two noise estimates, decided once from converged quantities.

**Rule.** ``lambda* = argmin U(lambda; sigma^2)`` (:mod:`service.core.search.risk`) with
``sigma = max(sigma_L, sigma_W)``: ``sigma_L`` the local fits' estimate
(:mod:`service.core.noise.estimate`), ``sigma_W`` Wahba's estimate ``phi / (c t)`` at the GCV
minimiser. Each is biased low in a known way and neither is biased high by noise: the local
quadratic fits follow noise of an edge length or more (``sigma_L`` 0.4-0.75 sigma at 1-2
edges), GCV fits correlated noise, outliers and the faint noise of flat CAD faces as shape
(``sigma_W`` 0.03-0.5 sigma). Chosen on the calibration half against the discrepancy
``tau0``, the knee, GCV and UPRE with either estimate alone (service/core/README.md).

**Decided from converged quantities.** :class:`RiskRule` reads the curves at the checkpoints of
a Lanczos run (data columns, plus ``p`` probe columns in a second recurrence stepped
alongside until the decision); ``lambda*`` is the minimiser over the lambdas where the Gauss
and Gauss-Radau rules agree (``phi`` and ``t``, within :data:`CONVERGED`: the models have
converged there), decided when it lies inside that region and two checkpoints in a row give
it within :data:`STABLE`. The minimiser is a root of ``U'``, a smooth function of the data, so
there is
no flip between far-apart answers. On the factorized path (:func:`polish`) the minimisers are
then refined by secant steps on the exact derivatives (solves with the factorization the
final solve needs anyway), so that ``lambda*`` is reproducible to ``1e-9`` whatever rounding
did to the recurrence: transformed inputs give the transformed output.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from service.core.linalg.lanczos_run import LanczosRun
from service.core.search.risk import RiskCurves, Rule, probe_block, run_rules

__all__ = ["CONVERGED", "STABLE", "RiskChoice", "RiskRule", "polish", "probes_for"]

Array = NDArray[np.float64]
#: Agreement of the Gauss and Gauss-Radau rules (``phi`` and ``t``) at the minimiser.
CONVERGED = 5e-3
#: Two checkpoints in a row agree on ``lambda*`` and ``sigma_W`` within this (relative).
STABLE = 5e-3
#: The agreement that makes the curves trusted for a starting estimate (factorized path).
ROUGH = 1e-2
#: Grid of the trusted region, and how far inside it a minimiser must lie (a minimum on its
#: edge is the model's, not the risk's).
TRUST_GRID = 241
EDGE = 1.2


def probes_for(size: int) -> int:
    """Probe columns: 8 below 20 000 unknowns (the factorized path: their solves are cheap
    next to a factorization), 2 above, where each probe column costs a product with ``M``
    per step as the data's column does (164K: 2.5 ms a column, linear in the columns) and
    the trace's relative spread, about ``sqrt(2 / (p df))`` with ``df`` in the thousands, is
    already a few per cent; the minimum of ``U`` is flat, so such an error in ``t'`` moves
    lambda* by a few per cent and the risk by much less."""
    return 8 if size < 20_000 else 2


@dataclass(frozen=True)
class RiskChoice:
    """The decided lambda and its evidence (internal frame).

    Attributes
    ----------
    lam : float
        ``lambda*``.
    sigma2_local, sigma2_wahba, sigma2 : float
        The two noise variances and the one used (their maximum).
    lam_gcv : float
        GCV's minimiser (where ``sigma_W`` is read).
    df : float
        ``tr(S H S) / mean(S^2)`` at ``lambda*``: the modes the smoothing keeps (per column).
    steps, products : int
        Lanczos steps at the decision and products of the probe recurrence.
    converged : bool
        Decided on converged curves (else at the cap, on the last ones).
    polished : int
        Evaluations of the exact derivatives (factorized path).
    phi : float
        ``phi(lambda*)`` (the curves', or exact once polished).
    """

    lam: float
    sigma2_local: float
    sigma2_wahba: float
    sigma2: float
    lam_gcv: float
    df: float
    steps: int
    products: int
    converged: bool
    polished: int = 0
    phi: float = math.nan

    def evidence(self, sigma_out: Callable[[float], float], lam_out: Callable[[float], float],
                 ) -> dict[str, float | int | bool]:  # fmt: skip
        """The Plan's evidence in the input's numbers."""
        return {
            "sigma_local": sigma_out(self.sigma2_local),
            "sigma_wahba": sigma_out(self.sigma2_wahba),
            "sigma": sigma_out(self.sigma2), "lambda": lam_out(self.lam),
            "lambda_gcv": lam_out(self.lam_gcv), "df": round(self.df, 3),
            "steps": self.steps, "probe_products": self.products, "converged": self.converged,
            "polish_steps": self.polished,
        }  # fmt: skip


class RiskRule:
    """The decision over the checkpoints of one run (module docstring).

    Parameters
    ----------
    apply_mt : callable
        ``V -> M_t V``.
    S : ndarray, shape (m,)
        The noise scale per unknown (``omega_i sigma_i / sigma`` in the frame).
    rho : ndarray, shape (m,)
        The invariant radius of each unknown's point (:func:`~.risk.invariant_radius`).
    columns : int
        Coordinate columns of the data.
    sigma2_local : float
        ``sigma_L^2`` in the internal frame.
    lo, hi : float
        The lambda interval searched.
    cap : int
        Steps after which the last curves decide.
    """

    def __init__(
        self, apply_mt: Callable[[Array], Array], S: Array, rho: Array, columns: int,
        sigma2_local: float, lo: float, hi: float, cap: int,
    ) -> None:  # fmt: skip
        self.count = probes_for(S.size)
        self.Z = probe_block(rho, self.count) * S[:, None]
        self.probes = LanczosRun(apply_mt, self.Z, keep_bytes=0)
        self.columns, self.s2, self.m = columns, float(np.sum(S**2)), S.size
        self.sigma2_local, self.lo, self.hi, self.cap = sigma2_local, lo, hi, cap
        self.last: tuple[float, float] | None = None
        self.choice: RiskChoice | None = None

    def step(self) -> None:
        """One step of the probe recurrence (alongside the data's)."""
        if self.choice is None and not self.probes.done:
            self.probes.step()

    def curves(self, data: Callable[[bool], Rule], order: int, radau: bool = False) -> RiskCurves:
        """The curves from the data's rule (``data(radau)``) and the probes' rule."""
        p = self.probes
        probes = run_rules(p.alphas, p.betas, p.beta0, p.length, radau)
        return RiskCurves(data(radau), probes, order, self.count, self.columns, self.s2)

    def update(
        self, data: Callable[[bool], Rule], order: int, steps: int, done: bool = False,
        stable: float = STABLE, strict: bool = True,
    ) -> bool:  # fmt: skip
        """Whether lambda* is decided after ``steps`` (then :attr:`choice` holds it).

        ``data(radau)`` gives the data columns' Gauss (Gauss-Radau) rule; ``strict``: the
        two rules must agree at the minimisers (else two checkpoints within ``stable`` do).
        """
        rc, rc_r = self.curves(data, order), self.curves(data, order, True)
        tol = CONVERGED if strict else ROUGH
        lo = _trusted(rc, rc_r, self.lo, self.hi, tol)
        lam_g = rc.gcv_min(lo, self.hi)
        s2w = rc.wahba_sigma2(lam_g)
        s2 = max(self.sigma2_local, s2w)
        lam = rc.upre_min(s2, lo, self.hi)
        inside = lo <= self.lo or (lam > lo * EDGE and lam_g > lo * EDGE)
        last, self.last = self.last, (lam, s2w)
        close = last is not None and _close(last[0], lam, stable) and _close(last[1], s2w, stable)
        ok = close and inside
        if ok or steps >= self.cap or done or self.probes.done:
            df = (self.s2 - float(rc.trace(np.asarray(lam)))) / max(self.s2 / self.m, 1e-300)
            self.choice = RiskChoice(lam, self.sigma2_local, s2w, s2, lam_g, df, steps,
                                     self.probes.products, bool(ok), 0,
                                     float(rc.phi(np.asarray(lam))))  # fmt: skip
            return True
        return False


def _trusted(gauss: RiskCurves, radau: RiskCurves, lo: float, hi: float, tol: float) -> float:
    """The smallest lambda of a log grid on ``[lo, hi]`` above which the Gauss and
    Gauss-Radau rules agree on ``phi`` and ``t`` within ``tol`` (the models have converged
    there; below it an unconverged model's minimum would be an artefact)."""
    grid = np.geomspace(lo, hi, TRUST_GRID)
    bad = np.zeros(grid.size, dtype=bool)
    for f, g in ((gauss.phi(grid), radau.phi(grid)), (gauss.trace(grid), radau.trace(grid))):
        bad |= np.abs(f - g) > tol * np.maximum(np.abs(f), 1e-300)
    if not bad.any():
        return lo
    last = int(np.flatnonzero(bad)[-1])
    return float(grid[min(last + 1, grid.size - 1)])


def _close(a: float, b: float, tol: float) -> bool:
    return abs(a - b) <= tol * max(abs(a), abs(b), 1e-300)


def polish(
    solve: Callable[[float, Array], Array], Q: Array, W: Array, order: int, choice: RiskChoice,
    columns: int, lo: float, hi: float,
) -> RiskChoice:  # fmt: skip
    """``choice`` with ``lambda_GCV`` and ``lambda*`` refined on the exact derivatives.

    ``solve(lam, V)`` returns ``(M_t + lam)^-1 V`` (Y-space, the factorization's); ``Q`` the
    data's ``c`` columns, ``W = S Z`` the probes (fixed, so the minimised functions are
    deterministic): the roots of their derivatives in ``log lambda`` nearest the curves'
    minimisers (:func:`_root_near`), to ``1e-10``.
    """
    count = W.shape[1]
    s2 = float(np.sum(W**2)) / max(count, 1)

    def exact(lam: float) -> tuple[float, float, float, float]:
        return _exact(solve, Q, W, order, lam, count)

    def dlog_v(x: float) -> float:
        phi, dphi, t, dt = exact(math.exp(x))
        return math.exp(x) * (dphi / phi - 2 * dt / t)

    lam_g, n1 = _root_near(dlog_v, choice.lam_gcv, lo, hi)
    phi, _, t, _ = exact(lam_g)
    s2w = phi / max(columns * t, 1e-300)
    s2 = max(choice.sigma2_local, s2w)

    def du(x: float) -> float:
        _, dphi, _, dt = exact(math.exp(x))
        return math.exp(x) * (dphi - 2 * columns * s2 * dt)

    lam, n2 = _root_near(du, choice.lam, lo, hi)
    return RiskChoice(lam, choice.sigma2_local, s2w, s2, lam_g, choice.df, choice.steps,
                      choice.products, choice.converged, n1 + n2, exact(lam)[0])  # fmt: skip


def _exact(solve: Callable[[float, Array], Array], Q: Array, W: Array, order: int, lam: float,
           count: int) -> tuple[float, float, float, float]:  # fmt: skip
    """``phi, phi', t, t'`` at ``lam`` by solves: ``G = I - lam (M_t + lam)^-1`` applied
    ``k`` times; ``phi = ||M_t^(k-1) (M_t+lam)^-k c||^2`` from the same chain on ``c``."""
    B = np.hstack([Q, W])
    R = solve(lam, B)  # (M_t + lam)^-1 [c, w]
    q = Q.shape[1]
    # data: y_1 = (M_t+lam)^-1 c, y_j = (M_t+lam)^-1 M_t y_(j-1) = y_(j-1) - lam (..)^-1 y_(j-1)
    y = R[:, :q]
    g = W - lam * R[:, q:]  # G w
    for _ in range(1, order):
        Z = solve(lam, np.hstack([y, g]))
        y = y - lam * Z[:, :q]
        g = g - lam * Z[:, q:]
    z = solve(lam, y)
    phi = float(np.sum(y * y))
    dphi = -2.0 * order * float(np.sum(y * z))
    t = float(np.sum(W * g)) / count
    dt = -order * float(np.sum(R[:, q:] * g)) / count
    return phi, dphi, t, dt


def _root_near(f: Callable[[float], float], lam0: float, lo: float, hi: float
               ) -> tuple[float, int]:  # fmt: skip
    """The root of the increasing ``f`` (a derivative at a minimum, in ``log lambda``)
    nearest ``lam0``: steps of 0.05, 0.1, 0.2, ... downhill until ``f`` changes sign, then the
    Brent's method to ``1e-8``; an end of ``[lo, hi]`` when the minimum
    is there. Returns the root and the evaluations of ``f``."""
    a, b = math.log(lo), math.log(hi)
    x0 = min(max(math.log(lam0), a), b)
    f0 = f(x0)
    n = 1
    if f0 == 0:
        return math.exp(x0), n
    step = -0.05 if f0 > 0 else 0.05
    x1, f1 = x0, f0
    while (f1 > 0) == (f0 > 0):
        x0, f0 = x1, f1
        x1 = min(max(x0 + step, a), b)
        if x1 == x0:  # at an end of the interval
            return math.exp(x1), n
        f1, n, step = f(x1), n + 1, 2 * step
    count = [n]

    def g(x: float) -> float:
        count[0] += 1
        return f(x)

    from scipy.optimize import brentq  # the factorized path only: small runs do not load it

    lo_x, hi_x = min(x0, x1), max(x0, x1)
    root = brentq(g, lo_x, hi_x, xtol=1e-8, rtol=1e-10, maxiter=60)
    return math.exp(root), count[0]
