"""``smooth_one()``: one run of the engine on one geometry, as stages in run order.

plan (:mod:`.plan`: every automatic choice, once) -> prepare (:mod:`.problem`: neighbourhoods
and ``L``, report section 4; free points, section 8; the system of eq. 4) -> target (tau of
eq. 3, :mod:`.search.target`) -> solve (lambda so that ``phi(lambda) = tau``, eqs. 15-17 and
section 6; the max-norm bound of section 9) -> finish (:mod:`.finish`: outliers, tangential
step, volume, clipping) -> report (:mod:`.checks.diagnostics`). Each stage takes records and
returns one; :class:`~service.core.run.Run` only keeps the clock, the progress callback and the
notes. The public ``smooth()`` (untiled or tiled) is :func:`service.core.entry.smooth`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from service.core.checks.diagnostics import diagnostics
from service.core.errors import TauOutOfRange
from service.core.finish.clip import clip_points
from service.core.finish.duplicates import join_duplicates
from service.core.finish.finished import Finished
from service.core.finish.outliers import Outliers, far_moved, outliers_of, place_outliers
from service.core.finish.residual import BackOff, back_off
from service.core.finish.tangential import relax_tangential
from service.core.finish.volume import preserve_measure
from service.core.frame import Frame
from service.core.geometry import Geometry
from service.core.linalg.cache import analysis_of
from service.core.linalg.resources import choose_solver
from service.core.noise.estimate import codimension
from service.core.operator.build import SmoothingOperator
from service.core.params import SmoothingParams
from service.core.params.rules import boundary_mode
from service.core.plan import Plan, make_plan, with_finish, with_problem, with_solution
from service.core.problem import Problem, prepare
from service.core.progress import ProgressCallback
from service.core.result import SmoothResult
from service.core.run import Run
from service.core.search.maxnorm import bound_deviation
from service.core.search.one_run_target import (
    NoiseModel,
    choose_and_solve,
    progress,
    sigma_of,
    solve_tau,
)
from service.core.search.one_run_target import applies as one_run_applies
from service.core.search.polyfilter import filter_system
from service.core.search.risk import invariant_radius
from service.core.search.risk_rule import RiskChoice
from service.core.search.roots import LambdaSearch
from service.core.search.target import (
    Solution,
    Target,
    check_range,
    find_lambda,
    gcv_search,
    out_of_range,
    resolve_tau,
)
from service.core.system.deviation import Deviation
from service.core.warnings import warning

__all__ = ["finish", "plan_and_prepare", "report", "smooth_one", "solve", "target", "tikhonov"]


def smooth_one(
    geometry: Geometry,
    params: SmoothingParams,
    progress: ProgressCallback | None = None,
    *,
    operator: SmoothingOperator | None = None,
    memory_limit: int | None = None,
) -> SmoothResult:
    """Smooth one geometry (report KU Leuven TW 451), untiled.

    ``X* = argmin ||L X||_F^2 + lambda ||D (X - P)||_F^2`` (eq. 4), fixed points eliminated
    (section 8), ``lambda`` given or found so that ``phi(lambda) = ||D(X - P)||_F^2 = tau``
    (eqs. 3, 15). ``progress`` gets a :class:`~service.core.progress.ProgressEvent` per stage
    and per lambda tried; ``operator`` (from
    :func:`~service.core.operator.build.build_operator`) is reused across tau; with
    ``solver="auto"`` a factor that would not fit ``memory_limit`` bytes selects CG.

    Raises
    ------
    ParameterError, TauOutOfRange, SolverError
    """
    run = Run(progress)
    run.emit("neighborhoods")
    plan, problem = plan_and_prepare(geometry, params, operator, step=run.step)
    run.step("noise")
    aim = target(problem, plan)
    run.emit("analysis", tau=aim.tau)
    solution = solve(problem, plan, aim, run, memory_limit)
    finished = finish(problem, plan, solution)
    if finished.backoff is not None:
        b = finished.backoff
        run.warn(warning("residual-backoff", b.describe(), points=int(b.points.size),
                         restored_rms=b.restored_rms, removed_rms=b.removed_rms))
    return report(problem, plan, run, solution, finished)


def plan_and_prepare(
    geometry: Geometry,
    params: SmoothingParams,
    operator: SmoothingOperator | None = None,
    *,
    step: Callable[[str], None] | None = None,
) -> tuple[Plan, Problem]:
    """The plan (:func:`~service.core.plan.make_plan`) and the problem it sets up
    (:func:`~service.core.problem.prepare`, told ``step("weights")`` when it gets to the data
    weights), the plan completed with what that decided."""
    plan = make_plan(geometry, params, tracks=operator is None)  # a given operator: its weights
    problem = prepare(geometry, plan.params, params.displacement, operator=operator, step=step)
    fell_back = problem.params.displacement != plan.params.displacement
    rows = boundary_mode(params.boundary, problem.params.displacement)
    if fell_back and rows != plan.params.boundary and problem.op.neighborhoods.boundary.any() \
            and operator is None:  # fmt: skip
        # an open mesh flat across itself: free displacement takes its boundary rows too
        free = params.model_copy(update={"displacement": "free"})
        plan = replace(make_plan(geometry, free), displacement=plan.displacement)
        problem = prepare(geometry, plan.params, "free")
    return with_problem(plan, problem), problem


def target(problem: Problem, plan: Plan) -> Target:
    """tau of eq. (3), resolved once in the input's frame (:func:`resolve_tau`)."""
    aim = resolve_tau(
        problem.params, problem.geometry, problem.fixed, problem.op, problem.weights
    )
    if problem.system.empty and plan.automatic_tau and aim.tau:
        aim = aim.noted("; but nothing can move (all fixed or uncoupled)")
    return aim


def solve(
    problem: Problem, plan: Plan, aim: Target, run: Run, memory_limit: int | None
) -> Solution:
    """Nothing to solve, the windowed-sinc filter, or the default strategy (:func:`tikhonov`:
    knee, lambda search, solve; the one place another strategy is swapped in)."""
    if problem.system.empty or (plan.automatic_tau and not aim.tau):
        return unchanged(problem, plan, aim, run)
    if problem.params.method == "windowed-sinc":
        return filtered(problem, aim, run)
    return tikhonov(problem, plan, aim, run, memory_limit)


def tikhonov(
    problem: Problem, plan: Plan, aim: Target, run: Run, memory_limit: int | None
) -> Solution:
    """Eq. (4) of order ``k``: lambda chosen by the automatic rule (the minimiser of the
    unbiased predictive risk, :mod:`~service.core.search.risk_rule`), found for a tau
    (section 6.3) or by GCV, the solution ``U`` (max-norm bounded, section 9)."""
    params, frame = problem.params, problem.frame
    solver = choose_solver(problem.system, params, memory_limit, run.warn)
    dev = Deviation(
        problem.system,
        solver=solver,
        order=params.order,
        reuse=params.search != "rational",
        symbolic=analysis_of,
    )
    dev.listener = run.listener(frame, aim.tau)
    seconds = 0.0
    one = one_run_applies(params, problem.system.size)
    try:
        search: LambdaSearch | None = None
        t0 = time.perf_counter()
        if plan.tau_rule.value == "risk":
            choice, search = choose_and_solve(dev, noise_model(problem, aim), one, progress(dev))
            if choice.lam > FULL_SMOOTHING * dev.floor:
                aim = risk_target(aim, choice, frame, search.phi)
            else:  # the risk's minimum at full smoothing: the discrepancy budget instead
                aim, search = aim.noted(FALLBACK), None
                dev = Deviation(problem.system, solver=solver, order=params.order,
                                symbolic=analysis_of)  # fmt: skip
        if search is None and one and aim.tau is not None and params.tau_rule != "gcv":
            try:
                search = solve_tau(dev, frame.tau_in(aim.tau), params.tolerance, progress(dev))
            except TauOutOfRange as exc:  # internal frame: the range's end in the input's
                raise out_of_range(params, aim.tau, frame.phi_out(exc.tau_max)) from None
        if params.tau_rule == "gcv":
            search, aim = gcv_search(dev, problem.geometry, params, problem.fixed, frame)
        elif search is None:
            search = find_lambda(dev, problem.op, problem.fixed, params, aim, frame, run.notes)
        seconds = time.perf_counter() - t0
    except TauOutOfRange as exc:
        if not plan.automatic_tau:
            raise
        aim = aim.noted(
            f"; no lambda above the floor meets it: phi(0) = {exc.tau_max:.6g}, the deviation "
            "of the fully smoothed shape, is within the estimated noise (the noise is as "
            "large as the shape)"
        )
        return unchanged(problem, plan, replace(aim, tau=None), run)
    run.emit("postprocess", tau=aim.tau, iteration=len(dev.history))
    dev.listener = run.listener(frame, aim.tau)
    return _bounded(problem, dev, Solution(aim, search, None, dev, None, seconds), run)


#: lambda* within this factor of the floor is full smoothing (the shape's own detail read as
#: risk): a 2-D track at 2 edges of noise went 332x the oracle's error there.
FULL_SMOOTHING = 10.0
FALLBACK = (
    "; the unbiased risk estimate is least at full smoothing (no lambda above the floor), "
    "which would flatten the shape: the discrepancy budget is used instead"
)


def noise_model(problem: Problem, aim: Target) -> NoiseModel:
    """The automatic rule's noise model per unknown of the system (internal frame): the
    scale ``omega_i sigma_i / sigma`` (signed as the data, below), the points' invariant
    radius (the probes' phase), the local fits' sigma^2 and the discrepancy budget."""
    system, frame = problem.system, problem.frame
    free = np.flatnonzero(~problem.fixed)
    rep = max(system.size // max(free.size, 1), 1)
    rows = np.repeat(free, rep)
    ts = problem.weights.tau_scale[rows] if problem.weights is not None else 1.0
    S = np.sqrt(system.d2) * ts
    if problem.params.displacement == "normal" and rep == 1 and system.r.shape[1] == 1:
        # a normal's sign is the eigensolver's: flipping n_i flips unknown i of the system
        # (a similarity) and of r; the probes' entries follow r's sign, so the trace estimate
        # is the same whatever signs the normals got (rotated input: 2.6e-2 sigma before)
        S = S * np.where(system.r[:, 0] < 0, -1.0, 1.0)
    sigma = (aim.sigma or 0.0) / frame.scale
    assert aim.tau is not None
    return NoiseModel(S, invariant_radius(problem.geometry.points[rows]), sigma**2,
                      frame.tau_in(aim.tau))  # fmt: skip


def risk_target(aim: Target, choice: RiskChoice, frame: Frame, phi: float) -> Target:
    """The target the automatic rule met: ``phi`` at lambda*, with the rule's words."""
    sigma = sigma_of(choice, frame.scale)
    local = math.sqrt(choice.sigma2_local) * frame.scale
    wahba = math.sqrt(choice.sigma2_wahba) * frame.scale
    tau = frame.phi_out(phi)
    how = (
        f"{aim.how}; lambda = {frame.lam_out(choice.lam):.6g} minimises the unbiased "
        f"predictive risk with sigma = {sigma:.6g}, the larger of the local fits' "
        f"{local:.6g} and Wahba's {wahba:.6g} (at the GCV minimiser); tau = phi there = "
        f"{tau:.6g} ({tau / aim.tau:.3g} x the discrepancy budget)"
        if aim.tau else f"{aim.how}; lambda by the unbiased predictive risk"
    )  # fmt: skip
    evidence = choice.evidence(lambda s2: math.sqrt(s2) * frame.scale, frame.lam_out)
    return Target(tau, how, sigma, evidence)


def _bounded(problem: Problem, dev: Deviation, sol: Solution, run: Run) -> Solution:
    """``sol`` with the solution ``U``; with ``max_deviation``, reweighted until every point is
    within it (section 9, :func:`~service.core.search.maxnorm.bound_deviation`)."""
    params, frame, search = problem.params, problem.frame, sol.search
    if params.max_deviation is None:
        return replace(sol, U=dev.solution(search.lam))
    aim = sol.target
    tau = None if aim.tau is None or params.tau_rule == "gcv" else frame.tau_in(aim.tau)
    hi = dev.system.lambda_ceiling(tau) if tau else search.lam
    res = bound_deviation(
        dev,
        params.max_deviation / frame.scale,
        search.lam,
        group=problem.system.size // max(int((~problem.fixed).sum()), 1),
        tau=tau,
        bracket=(dev.floor, max(hi, search.lam)),
        tolerance=params.tolerance,
    )
    run.warn(*(warning("max-deviation", said) for said in res.warnings))
    bound = {"max_deviation": params.max_deviation, "rounds": res.rounds, "clipped": res.clipped}
    converged = tau is None or abs(res.phi - tau) <= params.tolerance * tau
    history = [*search.history, *res.history]
    bounded = LambdaSearch(res.lam, res.phi, converged, history)
    return replace(sol, search=bounded, U=dev.system.U0 + res.E, bound=bound)


def filtered(problem: Problem, aim: Target, run: Run) -> Solution:
    """``method="windowed-sinc"``: a polynomial filter of ``L`` whose pass band meets tau
    (:func:`~service.core.search.polyfilter.filter_system`; products with ``M``, no solve)."""
    params, frame, system = problem.params, problem.frame, problem.system
    dev = Deviation(system, solver="cg")  # products with M (counted), no solve
    tau = None if aim.tau is None else frame.tau_in(aim.tau)
    lam = None if params.lam is None else frame.lam_in(params.lam)
    bound = system.phi0 if system.phi0 is not None else system.phi0_bound
    if tau is not None and bound is not None and tau >= bound:
        check_range(dev, problem.op, problem.fixed, params, aim, frame)
    U, search = filter_system(dev, params.laplacian, tau, lam, params.tolerance)
    if not search.converged:
        run.warn(warning("filter-tau-not-met", "windowed-sinc: no pass band of this degree meets "
                         "tau within tolerance", tolerance=params.tolerance))  # fmt: skip
    run.listener(frame, aim.tau)(search.lam, search.phi, 1)
    return Solution(aim, search, U, dev)


def unchanged(problem: Problem, plan: Plan, aim: Target, run: Run) -> Solution:
    """Nothing to do: every point fixed, a zero Laplacian, or an automatic tau that finds no
    noise or no valid budget (the reason is in ``tau_how`` and the notes).

    Raises
    ------
    TauOutOfRange
        A given tau or rms when nothing can move.
    """
    params = problem.params
    if plan.automatic_tau:
        reason = (aim.how or "nothing can move").removeprefix("automatic: ")
        run.warn(warning("not-smoothed", "not smoothed: " + reason))
        aim = replace(aim, tau=None)
    elif aim.tau is not None:
        raise TauOutOfRange(
            "nothing can move (every point is fixed or uncoupled): no smoothing factor can be "
            "met; valid range is empty",
            field="params.tau" if params.tau is not None else "params.rms",
            tau=aim.tau,
            tau_max=0.0,
        )
    else:
        run.warn(warning("nothing-to-smooth", "nothing to smooth: the input is returned unchanged"))
    return Solution(aim, LambdaSearch(float(params.lam or 0.0), 0.0, True, []))


def finish(problem: Problem, plan: Plan, sol: Solution) -> Finished:
    """The points in the input's frame: outliers pulled in by eq. (4) as ``omega_i -> 0`` or
    kept in place (:mod:`.finish.outliers`; kept points stay bit for bit through every step),
    the tangential step, volume/area kept (sections 8-9), the max-norm clip (section 9); and
    the outliers as they end up (:class:`~service.core.finish.outliers.Outliers`)."""
    if sol.U is None:
        X = problem.geometry.points.copy()
        return Finished(X, outliers=_outliers(problem, plan, sol, X))
    X = problem.points(sol.U)
    params = problem.params
    if params.method == "windowed-sinc":
        return Finished(X, outliers=_outliers(problem, plan, sol, X))
    if problem.weights is not None:  # outliers: kept (flag, drop) or pulled in, bounded
        X = place_outliers(problem.geometry.points, X, problem.op.L, problem.weights.pulled,
                           plan.outliers.value)
    X, backoff = _residual_test(problem, plan, sol, X)
    enabled = plan.tangential.value == "on"
    X, along = relax_tangential(
        problem.geometry, enabled, problem.op, problem.fixed, problem.frame, X, sol.search
    )
    if problem.geometry.kind == "cloud":  # a mesh's split vertices stay split (--no-weld)
        X = join_duplicates(problem.geometry.points, X, problem.geometry.fixed_mask())
    volume_scale, group = None, params.finish
    if group.preserve_volume:
        X, volume_scale = preserve_measure(problem.geometry, X)
    if group.max_deviation is not None:
        X, _ = clip_points(problem.geometry.points, X, group.max_deviation)
    kept = None
    if problem.weights is not None and plan.outliers.value != "pull":
        P = problem.geometry.points
        kept = problem.weights.outliers
        if problem.geometry.kind == "cloud":  # strays the residual test left undecided
            kept = far_moved(P, X, kept, sol.target.sigma, codimension(problem.geometry),
                             problem.weights.tau_scale)
        X = place_outliers(P, X, problem.op.L, kept[~problem.geometry.fixed_mask()[kept]],
                           plan.outliers.value)
    solved = X if backoff is None else backoff.undone(X)  # the count: the smoothing's own moves
    return Finished(X, volume_scale, along, _outliers(problem, plan, sol, solved, kept), backoff)


def _residual_test(
    problem: Problem, plan: Plan, sol: Solution, X: NDArray[np.float64]
) -> tuple[NDArray[np.float64], BackOff | None]:
    """Issue 40: where the removed displacement was shape, not noise, back off
    (:mod:`.finish.residual`): the automatic tau on surfaces in normal displacement (a tau,
    rms or lambda given is the caller's amount of smoothing, kept)."""
    g = problem.geometry
    if ((g.edges is not None and g.faces is None) or plan.displacement.value != "normal"
            or not plan.automatic_tau):
        return X, None
    dw = problem.weights
    out = dw.outliers if dw is not None else np.zeros(0, np.int64)
    return back_off(g.points, X, problem.op.L, out, g.fixed_mask(), sol.target.sigma,
                    codimension(g))


def _outliers(
    problem: Problem, plan: Plan, sol: Solution, X: NDArray[np.float64],
    kept: NDArray[np.int64] | None = None,
) -> Outliers | None:  # fmt: skip
    """The run's :class:`~service.core.finish.outliers.Outliers` for the final points ``X``."""
    dw = problem.weights
    if dw is None:
        return None
    return outliers_of(problem.geometry.points, X, dw.outliers, dw.pulled, plan.outliers.value,
                       dw.robust, sol.target.sigma, codimension(problem.geometry), kept)


def report(
    problem: Problem, plan: Plan, run: Run, sol: Solution, fin: Finished
) -> SmoothResult:
    """The :class:`SmoothResult`: the diagnostics' numbers and the completed plan. Its warnings
    in run order: the plan's and the set-up's, the outliers', the solve's, the checks', the
    solver's."""
    fields, checked = diagnostics(
        problem.geometry, problem.params, problem.op, problem.frame, run.t0, sol, fin,
        problem.n_fixed, problem.weights,
    )  # fmt: skip
    said = run.warnings
    outliers = () if fin.outliers is None else fin.outliers.warnings
    stats = sol.dev.stats.warnings if sol.dev is not None else []
    warnings = [*plan.warnings, *problem.warnings, *outliers, *said, *checked, *stats]
    plan = with_finish(with_solution(plan, sol.target, fields["solver"], said), fin.outliers)
    return SmoothResult(**fields, warnings=warnings, plan=plan)
