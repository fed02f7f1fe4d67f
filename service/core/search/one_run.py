"""The knee, lambda and the solution of the default path from one Lanczos run (issue 30).

One recurrence on ``M_t = D^-1 M D^-1`` from ``c = D^-1 r`` (:mod:`service.core.linalg.lanczos_run`,
one product per step for all coordinate columns) is checked every few steps:

1. **Knee** (automatic tau only): the flattest point of ``log phi`` against ``log lambda`` in
   the window ``KNEE_WINDOW x tau0`` around the discrepancy estimate ``tau0``, the rule of
   :func:`service.core.search.autotau.knee_tau`, taken from the Gauss and from the Gauss-Radau
   model separately. It is decided from converged quantities: when both models find a knee and
   their ``phi`` there agree within :data:`KNEE_RTOL` (the target is what the knee decides; on
   a plateau its lambda is ill-determined and its tau is not), or when neither finds one and
   both models put the window's ends at the same lambdas (within the same tolerance); at
   :data:`KNEE_CAP` steps the geometric mean of the two models decides, as the old rule did at
   its cap. (For order ``k > 1`` the Radau rule is no upper bound, but it converges to the same
   ``phi``: agreement still means convergence.) The new target is ``phi`` at the knee.
2. **lambda**: the root ``lambda_G`` of the Gauss model's ``phi = tau`` and ``lambda_R`` of the
   Radau model's; for order 1 they bracket the root of the exact ``phi`` (Golub and Meurant).
   Stop when ``lambda_R / lambda_G - 1 <= LAMBDA_RTOL`` **and** the model's bound of the solution
   error at ``lambda_G`` (:meth:`~service.core.linalg.lanczos_run.TikhonovModel.error_bound`)
   is at most ``rtol`` of the solution.
3. **Solution** ``E_k = D^-1 V a_k`` at ``lambda_G`` from the kept basis (or a second pass), then
   verified with its true residuals (one product with the block of the chain's vectors,
   :func:`~service.core.linalg.lanczos_run.true_residual_bound`): ``||D (E - E*)||_F <=
   rtol ||D E||_F`` holds rigorously for the vectors returned, whatever rounding and loss of
   orthogonality did to the run. If it does not (a ``float32`` basis at a very small lambda),
   the chain is polished by conjugate gradients from those vectors
   (:func:`~service.core.linalg.krylov.pcg`, same bound).

``rtol`` defaults to :data:`SOLUTION_RTOL` = 1e-3, the issue's bar ("the Tikhonov part within
1e-3 of the exact solution at the reported lambda"), not the 1e-10 of the factorized path: the
bound ``||r|| / lambda`` is pessimistic by up to ``mu_max / lambda`` (10K icosphere, rms 1.7
sigma: bound 1e-3 at 820 steps where the actual error was 5e-5; the 1e-10 bound took CG 2182
products). ``phi`` reported is ``||D E||^2`` of the vectors returned, never the model's.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from service.core.linalg.krylov import pcg
from service.core.linalg.lanczos_run import (
    BASIS_BYTES,
    LanczosRun,
    TikhonovModel,
    true_residual_bound,
)

__all__ = ["KNEE_CAP", "LAMBDA_RTOL", "SOLUTION_RTOL", "KneeRule", "OneRun", "knee_of", "one_run"]

Array = NDArray[np.float64]
SOLUTION_RTOL = 1e-3
LAMBDA_RTOL = 1e-4
#: The window of tau around the discrepancy estimate (as :data:`autotau.KNEE_WINDOW`).
KNEE_WINDOW = (0.4, 2.0)
KNEE_GRID = 240
#: The knee is decided when the Gauss and the Radau model put tau there within this (log);
#: "no knee" when neither has one and their windows agree within it at both ends.
KNEE_RTOL = 1e-2
#: Steps after which the knee is decided from the geometric mean of the two models.
KNEE_CAP = 400
#: The old rule's checkpoints (:data:`service.core.search.autotau.KNEE_CHECKPOINTS`).
GIVE_UP_AT = (40, 60, 90, 135, 200, 300)


@dataclass(frozen=True)
class OneRun:
    """What one Lanczos run decided and computed (internal frame).

    Attributes
    ----------
    lam : float
        ``lambda_G``, where the solution is the Galerkin (then verified) solution.
    tau : float
        The target met (the knee's ``phi`` when one was found).
    knee : float or None
        ``tau`` at the knee; ``None`` when none was asked or found.
    E : ndarray, shape (m, s)
        The deviation ``E_k(lambda)``.
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
    knee_steps : int or None
        Steps at which the knee was decided.
    """

    lam: float
    tau: float
    knee: float | None
    E: Array
    seeds: dict[str, Array]
    phi: float
    bound: float
    bracket: tuple[float, float]
    steps: int
    products: int
    converged: bool
    knee_steps: int | None = None
    notes: list[str] = field(default_factory=list)


def _flattest(lams: Array, phis: Array) -> int | None:
    """Index of the flattest point of ``log phi`` against ``log lambda`` (interior only), the
    rule of :func:`service.core.search.autotau.knee_tau`."""
    slope = np.gradient(np.log(np.maximum(phis, 1e-300)), np.log(lams))
    i = int(np.argmax(slope))
    return i if 2 <= i <= lams.size - 3 else None


def knee_of(
    model: TikhonovModel,
    tau0: float,
    lo: float,
    ceiling: Callable[[float], float],
    final: bool = False,
) -> tuple[bool, float | None]:
    """``(decided, tau at the knee or None)`` from the model (module docstring, step 1);
    ``ceiling(tau)``: a lambda with ``phi <= tau``."""
    lo_tau, hi_tau = KNEE_WINDOW[0] * tau0, KNEE_WINDOW[1] * tau0
    hi = ceiling(lo_tau)
    knees: list[tuple[float | None, float, float]] = []
    for radau in (False, True):
        lam_hi, lam_lo = model.root(lo_tau, lo, hi, radau), model.root(hi_tau, lo, hi, radau)
        if not lam_lo < lam_hi:
            knees.append((None, lam_lo, lam_hi))
            continue
        grid = np.geomspace(lam_lo, lam_hi, KNEE_GRID)
        gauss = np.maximum(model.phi(grid), 1e-300)
        both = np.sqrt(gauss * np.maximum(model.phi(grid, radau=True), 1e-300))
        phis = both if final else np.maximum(model.phi(grid, radau), 1e-300)
        i = _flattest(grid, phis)
        knees.append((None if i is None else float(phis[i]), lam_lo, lam_hi))
        if final:  # the geometric mean of the two models on the Gauss window (the old rule)
            return True, knees[0][0]
    if final:
        return True, knees[0][0]
    (tg, glo, ghi), (tr, rlo, rhi) = knees
    if tg is not None and tr is not None:
        return abs(math.log(tg / tr)) <= KNEE_RTOL, math.sqrt(tg * tr)
    window = abs(math.log(glo / rlo)) <= KNEE_RTOL and abs(math.log(ghi / rhi)) <= KNEE_RTOL
    inside = min(glo, rlo) > lo * (1 + KNEE_RTOL)  # not yet resolved down to the floor
    return tg is None and tr is None and window and inside, None


class KneeRule:
    """The knee decision over the checkpoints of one run (module docstring, step 1).

    "No knee" is also decided as the old rule did (:func:`service.core.search.autotau.knee_tau`:
    the geometric mean of the two models has no interior knee at two checkpoints in a row of
    :data:`GIVE_UP_AT`, from the fourth on): the low end of the window can take the models many
    steps to resolve (1M torus: below 200 steps both models put it at the lambda floor).
    """

    def __init__(self, tau0: float, lo: float, ceiling: Callable[[float], float]) -> None:
        self.tau0, self.lo, self.ceiling = tau0, lo, ceiling
        self.misses: list[bool] = []

    def update(self, model: TikhonovModel, steps: int) -> tuple[bool, float | None]:
        """``(decided, tau at the knee or None)`` after ``steps`` steps."""
        decided, knee = knee_of(model, self.tau0, self.lo, self.ceiling, steps >= KNEE_CAP)
        if decided or steps not in GIVE_UP_AT:
            return decided, knee
        _, mean = knee_of(model, self.tau0, self.lo, self.ceiling, final=True)
        self.misses.append(mean is None)
        if len(self.misses) >= 4 and self.misses[-1] and self.misses[-2]:
            return True, None
        return False, None


def _checkpoint(steps: int) -> bool:
    """Models every 10 steps up to 100, then every 10 % of the steps, and at
    :data:`GIVE_UP_AT`."""
    return steps % max(10, (steps // 10) // 10 * 10) == 0 or steps in GIVE_UP_AT


def one_run(
    apply_mt: Callable[[Array], Array],
    c: Array,
    d: Array,
    tau: float,
    lo: float,
    *,
    order: int = 1,
    knee: bool = False,
    rtol: float = SOLUTION_RTOL,
    max_steps: int = 5000,
    keep_bytes: int = BASIS_BYTES,
    basis_dtype: type = np.float32,
) -> OneRun:
    """Knee (when ``knee``), lambda and ``E_k`` from one Lanczos run (module docstring).

    Parameters
    ----------
    apply_mt : callable
        ``V -> M_t V`` for an ``(m, s)`` block (``M_t = D^-1 M D^-1``).
    c : ndarray, shape (m, s)
        ``D^-1 r`` (fixed points eliminated: ``r = b - M U0``).
    d : ndarray, shape (m, 1)
        The diagonal of ``D``.
    tau : float
        The target (internal frame); with ``knee`` the discrepancy estimate ``tau0``.
    lo : float
        The lambda floor (:meth:`~service.core.system.deviation.SmoothingSystem.lambda_floor`);
        the ceiling is ``||c||_F / sqrt(tau)`` (``phi <= ||c||^2 / lambda^2``).
    order : int
        Iterated Tikhonov order ``k``.
    """
    run = LanczosRun(apply_mt, c, keep_bytes, basis_dtype)
    cnorm = float(np.sqrt(np.einsum("ij,ij->", c, c)))
    ceiling = lambda t: max(cnorm / math.sqrt(t), lo)  # noqa: E731
    target: float | None = None if knee else tau
    rule = KneeRule(tau, lo, ceiling)
    knee_tau: float | None = None
    knee_steps: int | None = None
    lam_g = lam_r = ceiling(tau)
    converged = False
    while run.steps < max_steps and not run.done:
        run.step()
        if not (_checkpoint(run.steps) or run.done or run.steps == max_steps):
            continue
        model = run.model(order)
        if target is None:
            decided, knee_tau = rule.update(model, run.steps)
            if not decided:
                continue
            target, knee_steps = (knee_tau if knee_tau is not None else tau), run.steps
        hi = ceiling(target)
        lam_g = model.root(target, lo, hi)
        lam_r = model.root(target, lo, hi, radau=True)
        size = math.sqrt(max(float(model.phi(lam_g)), 1e-300))
        if abs(lam_r / lam_g - 1) <= LAMBDA_RTOL and model.error_bound(lam_g) <= rtol * size:
            converged = True
            break
    model = run.model(order)
    if target is None:  # the cap or an invariant subspace before the knee was decided
        _, knee_tau = knee_of(model, tau, lo, ceiling, final=True)
        target, knee_steps = (knee_tau if knee_tau is not None else tau), run.steps
        lam_g = model.root(target, lo, ceiling(target))
    Y = run.combine(model.chain(lam_g))
    bound = true_residual_bound(apply_mt, c, Y, lam_g)
    products = run.products + 1
    notes: list[str] = []
    size = float(np.sqrt(np.einsum("ij,ij->", Y[-1], Y[-1])))
    if bound > rtol * size:
        Y, bound, extra = _polish(apply_mt, c, Y, lam_g, rtol)
        products += extra
        size = float(np.sqrt(np.einsum("ij,ij->", Y[-1], Y[-1])))
        notes.append(f"Lanczos solution polished by conjugate gradients ({extra} products)")
    E = Y[-1] / d
    seeds = {("E1" if i == 0 else f"Z{i + 1}"): y / d for i, y in enumerate(Y[:-1])}
    return OneRun(
        lam=lam_g, tau=target, knee=knee_tau, E=E, seeds=seeds, phi=size**2,
        bound=bound / max(size, 1e-300), bracket=(lam_g, lam_r), steps=run.steps,
        products=products, converged=converged and bound <= rtol * size,
        knee_steps=knee_steps, notes=notes,
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
