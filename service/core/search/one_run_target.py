"""The default path's knee, lambda and solution from one Lanczos run (issue 30), as a target
and a lambda search the pipeline's solve stage uses like :func:`~.target.knee` and
:func:`~.target.find_lambda`'s.

When it applies (:func:`applies`: the automatic search and solver, a tau to meet, the
normalized Laplacian, no max-norm bound, at least :data:`ONE_RUN_FROM` unknowns), one
recurrence on ``M_t`` (:func:`~service.core.search.one_run.one_run`, with the products of the run's
solver so that they are counted) decides the knee, finds lambda and gives ``E_k(lambda)``,
which the :class:`~service.core.system.deviation.Deviation` adopts: no factorization. When the
cost model finds a factorized solve cheaper than finishing the recurrence
(:func:`~service.core.search.one_run.direct_cost`), or the run ends without meeting its bounds
or the tolerance asked (``phi`` of the adopted vectors within ``tolerance`` of tau: a 20K cloud
with ``tolerance = 1e-9`` stopped at 1.8e-7, not converged), only the target is kept and the
usual search runs from there (CHOLMOD or CG, as before).

Smaller systems keep the old path: below :data:`ONE_RUN_FROM` unknowns a factorization and
two solves cost under 0.3 s (10K: 0.1 s, 830 products' worth; ``direct_cost``), and the
results stay those of the factorized search (1e-10 accuracy).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from service.core.frame import Frame
from service.core.params import SmoothingParams
from service.core.search.one_run import OneRun, direct_cost, one_run
from service.core.search.roots import LambdaSearch
from service.core.search.target import Target
from service.core.system.deviation import Deviation

__all__ = ["ONE_RUN_FROM", "applies", "knee_and_solve"]

#: Unknowns from which the default solves in one Lanczos run.
ONE_RUN_FROM = 20_000


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


def knee_and_solve(
    dev: Deviation, aim: Target, frame: Frame, automatic: bool, tolerance: float
) -> tuple[Target, LambdaSearch | None]:
    """The target (moved to the knee when ``automatic``) and, when the run solved it, the
    lambda search whose ``E_k`` ``dev`` now holds; ``None`` leaves the solve to the caller."""
    assert aim.tau is not None
    system = dev.system
    inv_d = 1.0 / np.sqrt(system.d2)[:, None]
    res = one_run(
        lambda V: inv_d * dev.solver.matvec(inv_d * V),
        inv_d * system.r,
        np.sqrt(system.d2)[:, None],
        frame.tau_in(aim.tau),
        dev.floor,
        order=dev.order,
        knee=automatic,
        ceiling=system.lambda_ceiling,
        budget=direct_cost(system.size),
        report=_progress(dev),
    )
    if automatic:
        aim = _knee_target(aim, res, frame)
    if res.E is None or not res.converged or not dev.floor < res.lam:
        return aim, None
    dev.adopt(res.lam, res.E)
    phi = dev(res.lam)  # phi of the vectors adopted (recorded, reported to the listener)
    tau = frame.tau_in(aim.tau) if aim.tau is not None else phi
    if not abs(phi - tau) <= tolerance * tau:
        return aim, None  # a tolerance finer than the run resolves: the lambda search finishes
    return aim, LambdaSearch(res.lam, phi, True, list(dev.history))


def _knee_target(aim: Target, res: OneRun, frame: Frame) -> Target:
    """The target moved to the knee (the words of :func:`~.target.knee`; the run's target lies
    :data:`~service.core.search.knee_run.KNEE_RTOL` below the knee's tau)."""
    assert aim.tau is not None
    if res.knee is None:
        return aim.noted("; no knee of phi(lambda) near it: used as is")
    tau = frame.phi_out(res.tau)
    noted = aim.noted(
        f"; moved to the knee of phi(lambda) at tau = {frame.phi_out(res.knee):.6g}, "
        f"target {tau:.6g} ({tau / aim.tau:.3g} x), 1 % below it (the knee's resolution)"
    )
    return replace(noted, tau=tau, knee=tau / aim.tau)


def _progress(dev: Deviation) -> Callable[[float, float, int], None]:
    """The run's checkpoints as the lambda search's iterations: each model root and its
    Gauss-rule phi is recorded in ``dev.history`` (the report's ``history`` and
    ``iterations``) and reported to its listener, as a root finder's trial lambdas are."""

    def record(lam: float, phi: float, _checkpoint: int) -> None:
        dev.history.append((float(lam), float(phi)))
        if dev.listener is not None:
            dev.listener(float(lam), float(phi), len(dev.history))

    return record
