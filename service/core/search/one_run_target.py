"""The automatic lambda and the one-run solve as the pipeline's solve stage uses them
(issues 30, 37).

* :func:`choose_and_solve` (the automatic rule, :mod:`~service.core.search.risk_rule`): from
  :data:`ONE_RUN_FROM` unknowns (with the automatic search and solver, the normalized
  Laplacian, no max-norm bound: :func:`applies`) one Lanczos recurrence decides lambda* with
  its probes and gives ``E_k(lambda*)``, which the
  :class:`~service.core.system.deviation.Deviation` adopts: no factorization. Below it (or when
  the cost model hands the solve over, :func:`~service.core.search.one_run.direct_cost`) a
  recurrence without a kept basis decides lambda*, which secant steps on the exact derivatives
  refine (:func:`~service.core.search.risk_rule.polish`, with the factorization the solve
  makes anyway), and the system is solved there.
* :func:`solve_tau`: a given tau or rms on the one-run path (the root of ``phi = tau``).

Smaller systems keep factorized solves: below :data:`ONE_RUN_FROM` unknowns a factorization
and two solves cost under 0.3 s (10K: 0.1 s, 830 products' worth), and their results are those
of a 1e-10 solve.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from service.core.errors import TauOutOfRange
from service.core.linalg.lanczos_run import LanczosRun
from service.core.linalg.solver import Direct
from service.core.params import SmoothingParams
from service.core.search.one_run import _rules, direct_cost, one_run
from service.core.search.risk import RiskCurves
from service.core.search.risk_rule import STABLE, RiskChoice, RiskRule, polish
from service.core.search.roots import LambdaSearch
from service.core.system.deviation import Deviation

__all__ = ["ONE_RUN_FROM", "NoiseModel", "applies", "choose", "choose_and_solve", "solve_tau"]

Array = NDArray[np.float64]
#: Unknowns from which the default solves in one Lanczos run.
ONE_RUN_FROM = 20_000
#: Unknowns up to which the rule reads the exact spectrum (a dense eigendecomposition: 0.1 s
#: at 1000).
DENSE = 1000
#: Steps of the factorized path's recurrence at most: its estimate only starts the exact
#: roots (:func:`~service.core.search.risk_rule.polish`).
SMALL_CAP = 400
#: Agreement of two checkpoints (every 20 steps) that ends that recurrence.
SMALL_STABLE = 0.05
#: ``phi`` at the top of the lambda interval searched, relative to the discrepancy budget:
#: above it the smoothing is negligible.
TOP = 1e-4


def applies(params: SmoothingParams, size: int) -> bool:
    """Whether the one-run path serves this run (module docstring)."""
    return (
        size >= ONE_RUN_FROM
        and params.search == "auto"
        and params.solver == "auto"
        and params.tau_rule in ("auto", "tau", "rms")
        and params.laplacian == "normalized"
        and params.max_deviation is None
    )


@dataclass(frozen=True)
class NoiseModel:
    """What the rule knows of the noise, per unknown of the system (internal frame).

    Attributes
    ----------
    S : ndarray, shape (m,)
        ``omega_i sigma_i / sigma``: the noise scale in ``Q = D U0``.
    rho : ndarray, shape (m,)
        The invariant radius of each unknown's point (the probes' phase).
    sigma2 : float
        The local fits' ``sigma_L^2``.
    tau0 : float
        The discrepancy budget (sets the top of the lambda interval).
    """

    S: Array
    rho: Array
    sigma2: float
    tau0: float


def _mt(dev: Deviation) -> tuple[Callable[[Array], Array], Array, Array]:
    """``V -> M_t V``, ``c = D^-1 r`` and ``D`` (one scaling of the product when the weights
    are uniform)."""
    d = np.sqrt(dev.system.d2)[:, None]
    inv_d = 1.0 / d
    c = inv_d * dev.system.r
    if d.size and np.all(d == d[0, 0]):
        w = float(inv_d[0, 0]) ** 2
        return (lambda V: dev.solver.matvec(V) * w), c, d
    return (lambda V: inv_d * dev.solver.matvec(inv_d * V)), c, d


def _rule(dev: Deviation, noise: NoiseModel, cap: int) -> RiskRule:
    apply_mt, c, _ = _mt(dev)
    hi = max(dev.system.lambda_ceiling(TOP * noise.tau0), 10 * dev.floor)
    return RiskRule(apply_mt, noise.S, noise.rho, c.shape[1], noise.sigma2, dev.floor, hi, cap)


def exact_choice(dev: Deviation, noise: NoiseModel) -> RiskChoice:
    """lambda* from the exact spectrum of ``M_t`` (up to :data:`DENSE` unknowns: the
    recurrence's models of a curve's clustered spectrum need more steps than there are
    unknowns): ``phi`` from the data's projections, ``t = sum_i (V^T S^2 V)_ii g(mu_i)``
    exactly (no probes), so the rule is deterministic to rounding."""
    m = dev.system.size
    d = np.sqrt(dev.system.d2)[:, None]
    Mt = dev.solver.matvec(np.eye(m) / d) / d
    mu, V = np.linalg.eigh(0.5 * (Mt + Mt.T))
    mu = np.maximum(mu, 0.0)
    c = dev.system.r / d
    data = (mu, np.sum((V.T @ c) ** 2, axis=1))
    probes = (mu, (V**2).T @ noise.S**2)
    rc = RiskCurves(data, probes, dev.order, 1, c.shape[1], float(np.sum(noise.S**2)))
    lo = dev.floor
    hi = max(dev.system.lambda_ceiling(TOP * noise.tau0), 10 * lo)
    lam_g = rc.gcv_min(lo, hi)
    s2w = rc.wahba_sigma2(lam_g)
    s2 = max(noise.sigma2, s2w)
    lam = rc.upre_min(s2, lo, hi)
    df = float(np.sum(noise.S**2) - rc.trace(np.asarray(lam))) / max(
        float(np.mean(noise.S**2)), 1e-300)
    return RiskChoice(lam, noise.sigma2, s2w, s2, lam_g, df, 0, 0, True, 0,
                      float(rc.phi(np.asarray(lam))))  # fmt: skip


def choose(dev: Deviation, noise: NoiseModel, refine: bool = True) -> RiskChoice:
    """lambda* without solving at it. With a factorizing solver: a short recurrence on the
    data and the probes (no basis kept, :data:`SMALL_CAP` steps at most) whose estimate,
    stable to 5 %, starts the roots of the exact derivatives (:func:`~.risk_rule.polish`);
    with conjugate gradients (a memory limit), the recurrence until the rule decides on
    converged curves."""
    if dev.system.size <= DENSE:
        return exact_choice(dev, noise)
    apply_mt, c, d = _mt(dev)
    direct = isinstance(dev.solver, Direct)
    cap = min(SMALL_CAP if direct else 5000, 2 * dev.system.size + 20)
    rule = _rule(dev, noise, cap)
    run = LanczosRun(apply_mt, c, keep_bytes=0)
    check = 40
    while rule.choice is None:
        run.step()
        rule.step()
        if run.steps >= check or run.done:
            check = run.steps + (40 if direct else max(10, run.steps // 10))
            tol = SMALL_STABLE if direct else STABLE
            rule.update(_rules(run), dev.order, run.steps, run.done, tol, not direct)
    assert rule.choice is not None
    if not direct or not refine:
        return rule.choice
    return polish(_solver_y(dev, d), c, rule.Z, dev.order, rule.choice, c.shape[1], rule.lo,
                  rule.hi)  # fmt: skip


def _solver_y(dev: Deviation, d: Array) -> Callable[[float, Array], Array]:
    """``(lam, V) -> (M_t + lam)^-1 V = D K(lam)^-1 D V`` with the run's factorization, made
    at each new lambda (a factorization of these systems costs about two solves of the
    probe block; the factor of a nearby lambda as a preconditioner took 10 steps)."""
    solver = dev.solver
    assert isinstance(solver, Direct)

    def solve(lam: float, V: Array) -> Array:
        if solver.lam_factored != lam:
            solver.factor(lam)
        return d * solver.solve(lam, d * V)

    return solve


def choose_and_solve(
    dev: Deviation, noise: NoiseModel, one: bool, report: Callable[[float, float, int], None],
) -> tuple[RiskChoice, LambdaSearch]:  # fmt: skip
    """lambda* and the solution there (module docstring); ``one``: the one-run path
    applies (:func:`applies`)."""
    if not one:
        choice = choose(dev, noise)
        return choice, LambdaSearch(choice.lam, dev(choice.lam), True, list(dev.history))
    apply_mt, c, d = _mt(dev)
    rule = _rule(dev, noise, 5000)
    res = one_run(apply_mt, c, d, noise.tau0, dev.floor, order=dev.order, rule=rule,
                  ceiling=dev.system.lambda_ceiling, budget=direct_cost(dev.system.size),
                  report=report)  # fmt: skip
    assert rule.choice is not None
    choice = rule.choice
    if res.E is None or not res.converged:  # the cost model handed the solve over
        return choice, LambdaSearch(choice.lam, dev(choice.lam), True, list(dev.history))
    dev.adopt(res.lam, res.E)
    phi = dev(res.lam)  # phi of the vectors adopted (recorded, reported to the listener)
    return choice, LambdaSearch(res.lam, phi, True, list(dev.history))


def solve_tau(
    dev: Deviation, tau: float, tolerance: float, report: Callable[[float, float, int], None],
) -> LambdaSearch | None:  # fmt: skip
    """A given tau (internal frame) on the one-run path: the root of ``phi = tau`` and its
    solution; ``None`` leaves the solve to the usual search (the cost model handed it over, the
    run ended without meeting its bounds, or ``phi`` of the adopted vectors is not within
    ``tolerance`` of tau: a 20K cloud with ``tolerance = 1e-9`` stopped at 1.8e-7)."""
    apply_mt, c, d = _mt(dev)
    res = one_run(apply_mt, c, d, tau, dev.floor, order=dev.order,
                  ceiling=dev.system.lambda_ceiling, budget=direct_cost(dev.system.size),
                  report=report)  # fmt: skip
    if res.at_floor:  # tau is not below phi(0) (the model's, converged)
        raise TauOutOfRange("tau is not below phi(0)", field="params.tau", tau=tau,
                            tau_max=float(res.tau))
    if res.E is None or not res.converged:
        return None
    dev.adopt(res.lam, res.E)
    phi = dev(res.lam)
    if not abs(phi - tau) <= tolerance * tau:
        return None
    return LambdaSearch(res.lam, phi, True, list(dev.history))


def progress(dev: Deviation) -> Callable[[float, float, int], None]:
    """The run's checkpoints as the lambda search's iterations: each model lambda and its
    Gauss-rule phi is recorded in ``dev.history`` (the report's ``history`` and
    ``iterations``) and reported to its listener, as a root finder's trial lambdas are."""

    def record(lam: float, phi: float, _checkpoint: int) -> None:
        dev.history.append((float(lam), float(phi)))
        if dev.listener is not None:
            dev.listener(float(lam), float(phi), len(dev.history))

    return record


def sigma_of(choice: RiskChoice, scale: float) -> float:
    """The noise level the rule used, in the input's units."""
    return math.sqrt(max(choice.sigma2, 0.0)) * scale
