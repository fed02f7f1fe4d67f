"""lambda, the solution and (for the automatic rule) the choice of lambda from one Lanczos
run (issues 30, 37).

One recurrence on ``M_t = D^-1 M D^-1`` from ``c = D^-1 r`` (:mod:`service.core.linalg.lanczos_run`,
one product per step for all coordinate columns) is checked every few steps:

1. **lambda***: with the automatic rule, :class:`~service.core.search.risk_rule.RiskRule` (its
   probe recurrence stepped alongside) decides lambda from converged quantities; else the
   root ``lambda_G`` of the Gauss model's ``phi = tau`` and ``lambda_R`` of the Radau
   model's, which for order 1 bracket the root of the exact ``phi`` (Golub and Meurant).
2. Stop when lambda is decided (``lambda_R / lambda_G - 1 <= LAMBDA_RTOL`` for a root) **and**
   the model's bound of the solution error at it
   (:meth:`~service.core.linalg.lanczos_run.TikhonovModel.error_bound`) is at most ``rtol`` of
   the solution.
3. **Solution** ``E_k = D^-1 V a_k`` at ``lambda_G`` from the kept basis (or a second pass), then
   verified with its true residuals (one product with the block of the chain's vectors,
   :func:`~service.core.linalg.lanczos_run.true_residual_bound`): ``||D (E - E*)||_F <=
   rtol ||D E||_F`` holds rigorously for the vectors returned, whatever rounding and loss of
   orthogonality did to the run. If it does not (a ``float32`` basis at a very small lambda),
   the chain is polished by conjugate gradients from those vectors
   (:func:`~service.core.linalg.krylov.pcg`, same bound).

**Cost model**: with a ``budget`` (products that a factorized solve would cost), once the
target is set the run extrapolates the decay of the error bound over its last checkpoints and
stops when the solution would cost more than twice the budget (or has cost the budget): it
returns lambda and the target with ``E = None``, and the caller solves directly (a heavy
target at a small lambda needs ``O(sqrt(mu_max / lambda))`` steps: 164K icosphere at rms = 1.7
sigma, more than 5000).

``rtol`` defaults to :data:`SOLUTION_RTOL` = 1e-3, the issue's bar ("the Tikhonov part within
1e-3 of the exact solution at the reported lambda"), not the 1e-10 of the factorized path: the
bound ``||r|| / lambda`` is pessimistic by up to ``mu_max / lambda`` (10K icosphere, rms 1.7
sigma: bound 1e-3 at 820 steps where the actual error was 5e-5; the 1e-10 bound took CG 2182
products). ``phi`` reported is ``||D E||^2`` of the vectors returned, never the model's.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from service.core.linalg.krylov import pcg
from service.core.linalg.lanczos_run import (
    BASIS_BYTES,
    LanczosRun,
    TikhonovModel,
    true_residual_bound,
)
from service.core.search.risk import run_rules
from service.core.search.risk_rule import RiskRule

__all__ = ["LAMBDA_RTOL", "SOLUTION_RTOL", "OneRun", "direct_cost", "one_run"]

Array = NDArray[np.float64]
SOLUTION_RTOL = 1e-3
LAMBDA_RTOL = 1e-4


@dataclass(frozen=True)
class OneRun:
    """What one Lanczos run decided and computed (internal frame).

    Attributes
    ----------
    lam : float
        ``lambda_G``, where the solution is the Galerkin (then verified) solution (the
        rule's lambda* when a rule decided it).
    tau : float
        The target met (with a rule: the model's ``phi`` at lambda*).
    E : ndarray, shape (m, s), or None
        The deviation ``E_k(lambda)``; ``None`` when the cost model left the solve to the
        caller (``lam`` is then the model's root).
    seeds : dict
        Warm starts ``D^-1 y_i`` (``"Z2"``, ... as :class:`~service.core.system.deviation.Deviation`
        names them; ``"E1"`` for ``E_1``).
    phi : float
        ``||D E||_F^2`` of ``E``.
    bound : float
        Rigorous ``||D (E - E*)||_F / ||D E||_F`` (true residuals).
    bracket : tuple of float
        ``(lambda_G, lambda_R)`` at the stop.
    steps, products : int
        Lanczos steps and products with ``M`` (second pass, check and polish included).
    converged : bool
        Both stopping rules met within ``max_steps``.
    decided_at : int
        Steps at which the rule decided lambda (0 without a rule).
    at_floor : bool
        tau is not below ``phi(0)``: the root stayed at the floor on a converged model
        (``tau`` is then that model's ``phi(0)``; no solution).
    polished : int
        Products of a conjugate-gradient polish of the vectors (0: none was needed).
    """

    lam: float
    tau: float
    E: Array | None
    seeds: dict[str, Array]
    phi: float
    bound: float
    bracket: tuple[float, float]
    steps: int
    products: int
    converged: bool
    decided_at: int = 0
    polished: int = 0
    at_floor: bool = False


def direct_cost(size: int) -> int:
    """Products that one CHOLMOD analysis, factorization and two solves cost on the default's
    systems (measured on noisy icospheres and the 1M torus, one thread: 830 products at 10K,
    990 at 41K, 1230 at 164K, 3300 at 1M unknowns; ``52 n^0.3`` within 1.6x of each)."""
    return int(52 * max(size, 1) ** 0.3)


def _checkpoint(steps: int, trail: list[tuple[int, float]], rtol: float) -> int:
    """The step of the next model after one at ``steps``: every 10 steps up to 100, then about
    every 10 % of the steps (a model costs ``O(j^2)`` per column: at 1300 steps ~25 ms); once
    the solve has two checkpoints (``trail``: steps and error bounds), where the log-linear
    decay of the bound over the last two reaches ``rtol`` (from 2 % to 25 % of the steps
    ahead: Lanczos converges superlinearly, so the prediction is late rather than early)."""
    if steps < 100:
        return steps + 10
    ahead = max(20, steps // 10 // 10 * 10)
    if trail and trail[-1][1] <= rtol:  # only lambda's bracket to close
        return steps + max(10, steps // 50)
    if len(trail) >= 2:
        (j0, e0), (j1, e1) = trail[-2:]
        rate = math.log(e0 / e1) / max(j1 - j0, 1) if e1 > 0 and e0 > e1 else 0.0
        if rate > 0:
            need = math.log(e1 / rtol) / rate
            ahead = int(min(max(need, 10, steps // 50), max(20, steps // 4)))
    return steps + ahead


def one_run(
    apply_mt: Callable[[Array], Array],
    c: Array,
    d: Array,
    tau: float,
    lo: float,
    *,
    order: int = 1,
    rule: RiskRule | None = None,
    ceiling: Callable[[float], float] | None = None,
    rtol: float = SOLUTION_RTOL,
    max_steps: int = 5000,
    budget: int | None = None,
    keep_bytes: int = BASIS_BYTES,
    basis_dtype: type = np.float32,
    report: Callable[[float, float, int], None] | None = None,
) -> OneRun:
    """lambda* (with a ``rule``) or the lambda of ``phi = tau``, and ``E_k``, from one
    Lanczos run (module docstring).

    Parameters
    ----------
    apply_mt : callable
        ``V -> M_t V`` for an ``(m, s)`` block (``M_t = D^-1 M D^-1``).
    c : ndarray, shape (m, s)
        ``D^-1 r`` (fixed points eliminated: ``r = b - M U0``).
    d : ndarray, shape (m, 1)
        The diagonal of ``D``.
    tau : float
        The target (internal frame); ignored with a ``rule``.
    lo : float
        The lambda floor (:meth:`~service.core.system.deviation.SmoothingSystem.lambda_floor`).
    order : int
        Iterated Tikhonov order ``k``.
    rule : RiskRule, optional
        The automatic lambda (:mod:`~service.core.search.risk_rule`), stepped alongside and
        asked at every checkpoint until it decides; lambda is then fixed.
    ceiling : callable, optional
        ``tau -> ||c||_F / sqrt(tau)`` (``phi <= ||c||^2 / lambda^2``), by default from ``c``.
    budget : int, optional
        Products after lambda is set beyond which the solve is left to the caller
        (module docstring; :func:`direct_cost` estimates a factorized solve's).
    report : callable, optional
        ``report(lambda, phi, checkpoint)`` at every checkpoint once lambda is set (progress
        only, nothing is decided from it).
    """
    run = LanczosRun(apply_mt, c, keep_bytes, basis_dtype)
    if ceiling is None:
        cnorm = float(np.linalg.norm(c))
        ceiling = lambda t: cnorm / math.sqrt(t)  # noqa: E731
    top = lambda t: max(ceiling(t), lo)  # noqa: E731
    fixed: float | None = None
    decided_at = 0
    lam_g = lam_r = top(tau) if tau > 0 else lo
    trail: list[tuple[int, float]] = []
    floor_phi: list[float] = []
    stop = ""
    check = _checkpoint(0, [], rtol)
    while run.steps < max_steps and not run.done and not stop:
        run.step()
        if rule is not None and fixed is None:
            rule.step()
        if run.steps < check and not run.done:
            continue
        if rule is not None and fixed is None:  # the rules only: no eigenvectors until decided
            check = _checkpoint(run.steps, [], rtol)
            if not rule.update(_rules(run), order, run.steps, run.done):
                continue
            assert rule.choice is not None
            fixed, decided_at = rule.choice.lam, run.steps
        model = run.model(order)
        lam_g = fixed if fixed is not None else model.root(tau, lo, top(tau))
        if fixed is None and _at_floor(model, lam_g, lo, floor_phi):
            stop = "floor"  # tau not below phi(0): no lambda above the floor meets it
            break
        size = math.sqrt(max(float(model.phi(lam_g)), 1e-300))
        err = model.error_bound(lam_g) / size
        trail.append((run.steps, err))
        check = _checkpoint(run.steps, trail, rtol)
        if report is not None:
            report(lam_g, size * size, len(trail))
        if err <= rtol:  # the Radau rule (a second eigendecomposition) only when needed
            lam_r = lam_g if fixed is not None else model.root(tau, lo, top(tau), radau=True)
            if abs(lam_r / lam_g - 1) <= LAMBDA_RTOL:
                stop = "converged"
        elif budget is not None and lam_g > lo and _over_budget(trail, rtol, run, decided_at,
                                                                budget):  # fmt: skip
            stop = "budget"
    if rule is not None and fixed is None:  # max_steps before the rule decided: the last curves
        rule.update(_rules(run), order, run.steps, True)
        assert rule.choice is not None
        fixed, decided_at = rule.choice.lam, run.steps
        lam_g = lam_r = fixed
    model = run.model(order)
    target = float(model.phi(lam_g)) if fixed is not None else tau
    if stop == "floor":  # the model's phi(0): what the caller reports as the range's end
        target = floor_phi[-1]
    probes = rule.probes.products if rule is not None else 0
    products = run.products + probes
    if stop in ("budget", "floor") or (fixed is None and not lam_g > lo):
        return OneRun(lam_g, target, None, {}, math.nan, math.inf, (lam_g, lam_r), run.steps,
                      products, False, decided_at, 0, stop == "floor")  # fmt: skip
    if stop == "converged":  # the fewest steps whose solution meets the bound (the rule may
        # have run the recurrence past the solution's convergence: a shorter second pass)
        above = [j for j, e in trail if e > rtol]  # the last checkpoint short of the bound
        model = _shortest(run, order, lam_g, rtol, above[-1] + 1 if above else 1)
    res = _solution(run, model, c, d, lam_g, lam_r, target, decided_at, rtol,
                    stop == "converged")  # fmt: skip
    return replace(res, products=res.products + probes)


def _at_floor(model: TikhonovModel, lam: float, lo: float, seen: list[float]) -> bool:
    """Whether the root sits at the floor on a converged model: ``phi(lo)`` of this checkpoint
    within 1e-3 of the last one's (``seen`` keeps it). Then tau is not below ``phi(0)`` and the
    run stops instead of spending its budget on a solve at the floor."""
    if lam > lo:
        seen.clear()
        return False
    phi = float(model.phi(lo))
    last = seen[-1] if seen else None
    seen.append(phi)
    return last is not None and abs(phi - last) <= 1e-3 * abs(phi)


def _rules(run: LanczosRun) -> Callable[[bool], tuple[Array, Array]]:
    """The data columns' Gauss (``radau=False``) or Gauss-Radau rule after the steps done
    (nodes and weights only: :func:`~service.core.search.risk.run_rules`)."""
    return lambda radau: run_rules(run.alphas, run.betas, run.beta0, run.length, radau)


def _shortest(run: LanczosRun, order: int, lam: float, rtol: float, lo: int = 1) -> TikhonovModel:
    """The model of the fewest steps whose error bound at ``lam`` is at most ``rtol`` of its
    solution (bisection on the steps; the bound decreases with them in practice, and the
    caller verifies the vectors anyway); from ``lo`` steps on."""

    def ok(j: int) -> bool:
        m = run.model(order, j)
        return m.error_bound(lam) <= rtol * math.sqrt(max(float(m.phi(lam)), 1e-300))

    hi = run.steps
    while lo < hi:
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if ok(mid) else (mid + 1, hi)
    return run.model(order, hi)


def _over_budget(
    trail: list[tuple[int, float]], rtol: float, run: LanczosRun, start: int, budget: int
) -> bool:
    """Whether finishing the solve (the steps still needed, plus a second pass over all of them
    when the basis is not kept) costs more than ``budget`` products: spent already, or
    predicted at more than twice the budget from the log-linear decay of the error bound over
    the last (up to four, at least three) checkpoints; ``start``: the steps done when the
    target was set. Lanczos converges superlinearly, so early extrapolations overestimate:
    the factor 2 keeps them from handing over a solve that was about to converge."""
    steps = run.steps
    if steps - start >= budget:
        return True
    if len(trail) < 3:
        return False
    x = np.array([t[0] for t in trail[-4:]], dtype=np.float64)
    y = np.log(np.maximum([t[1] for t in trail[-4:]], 1e-300))
    rate = -float(np.polyfit(x, y, 1)[0])
    if not rate > 0:
        return True
    need = steps + max(math.log(trail[-1][1] / rtol), 0.0) / rate
    cost = (need - steps) + (0 if need <= run.keep_steps else need)
    return cost > 2 * budget


def _solution(
    run: LanczosRun, model: TikhonovModel, c: Array, d: Array, lam_g: float, lam_r: float,
    target: float, decided_at: int, rtol: float, converged: bool,
) -> OneRun:  # fmt: skip
    """``E_k`` at ``lam_g`` from the basis, verified by its true residuals (polished if
    needed)."""
    Y = run.combine(model.chain(lam_g))
    bound = true_residual_bound(run.apply_mt, c, Y, lam_g)
    products = run.products + 1
    size = float(np.sqrt(np.einsum("ij,ij->", Y[-1], Y[-1])))
    extra = 0
    if bound > rtol * size:
        Y, bound, extra = _polish(run.apply_mt, c, Y, lam_g, rtol)
        products += extra
        size = float(np.sqrt(np.einsum("ij,ij->", Y[-1], Y[-1])))
    E = Y[-1] / d
    seeds = {("E1" if i == 0 else f"Z{i + 1}"): y / d for i, y in enumerate(Y[:-1])}
    return OneRun(
        lam=lam_g, tau=target, E=E, seeds=seeds, phi=size**2,
        bound=bound / max(size, 1e-300), bracket=(lam_g, lam_r), steps=run.steps,
        products=products, converged=converged and bound <= rtol * size,
        decided_at=decided_at, polished=extra,
    )  # fmt: skip


def _polish(
    apply_mt: Callable[[Array], Array], c: Array, Y: list[Array], lam: float, rtol: float
) -> tuple[list[Array], float, int]:
    """The chain ``y_i = (M_t + lambda)^-1 M_t y_(i-1)`` (``y_0``'s image replaced by ``c``)
    solved by CG from ``Y``, each to ``rtol / k`` of its size on the rigorous bound."""
    k = len(Y)
    ones = np.ones(c.shape[0])
    apply_k = lambda X: apply_mt(X) + lam * X  # noqa: E731
    out: list[Array] = []
    products = 0
    rhs = c
    bound = 0.0
    for i in range(k):
        y, used, _ = pcg(apply_k, rhs, lambda R: R, lam, ones, x0=Y[i], rtol=rtol / k)
        products += used
        out.append(y)
        if i + 1 < k:
            rhs = apply_mt(y)
            products += 1
    bound = true_residual_bound(apply_mt, c, out, lam)
    return out, bound, products + 1
