"""``smooth()``: the single entry point of the engine (exported as ``service.core.smooth``).

Pipeline (report sections 4-8): neighbourhoods and the Laplacian (:mod:`.operator`) -> the free
points (fixed ones eliminated, section 8) -> the smoothing system (:mod:`.system`) -> lambda
(given, or searched so that ``phi(lambda) = tau``, :mod:`.tau`) -> the points ``X`` -> optional
volume/area rescaling -> diagnostics. Everything between the operator and ``X`` runs in the
internal frame of :mod:`.frame`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from service.core.checks.diagnostics import diagnostics
from service.core.errors import ParameterError, TauOutOfRange
from service.core.finish.clip import clip_points
from service.core.finish.tangential import relax_tangential
from service.core.finish.volume import check_preservable, preserve_measure
from service.core.frame import Frame
from service.core.geometry import Geometry
from service.core.linalg.cache import analysis_of
from service.core.linalg.resources import choose_solver
from service.core.noise.robust import DataWeights, data_weights, pull_in
from service.core.operator.build import (
    SmoothingOperator,
    build_laplacian,
    build_operator,
    operator_key,
)
from service.core.params import SmoothingParams
from service.core.progress import ProgressCallback
from service.core.result import SmoothResult
from service.core.run import Run
from service.core.search.maxnorm import bound_deviation
from service.core.search.polyfilter import filter_system
from service.core.search.roots import LambdaSearch
from service.core.search.target import check_range, find_lambda, gcv_search, knee, resolve_tau
from service.core.system.deviation import Deviation, SmoothingSystem
from service.core.system.displacement import auto_system, normal_mode, resolve_displacement
from service.core.system.elimination import laplacian_system

__all__ = [
    "Problem",
    "ProgressCallback",
    "build_laplacian",
    "build_operator",
    "prepare",
    "smooth",
]

Array = NDArray[np.float64]


def smooth(
    geometry: Geometry,
    params: SmoothingParams,
    progress: ProgressCallback | None = None,
    *,
    operator: SmoothingOperator | None = None,
    memory_limit: int | None = None,
) -> SmoothResult:
    """Smooth points, curves or meshes (report KU Leuven TW 451).

    Solves ``X* = argmin ||L X||_F^2 + lambda ||D (X - P)||_F^2`` (eq. 4): ``L`` the chosen
    Laplacian (section 4), ``D`` the per-point weights, fixed points eliminated (section 8),
    ``lambda`` given or found so that ``phi(lambda) = ||D(X - P)||_F^2 = tau`` (eqs. 3, 15).
    Steps: neighbourhoods and L -> free points -> system -> lambda -> X -> diagnostics.

    Parameters
    ----------
    geometry : Geometry
    params : SmoothingParams
    progress : callable, optional
        Called with a :class:`~service.core.progress.ProgressEvent` per stage and per lambda
        tried; from the ``analysis`` stage on ``event.tau`` is the resolved target.
    operator : SmoothingOperator, optional
        From :func:`build_operator` for this geometry and build parameters (reuse across tau).
    memory_limit : int, optional
        Bytes for the run: with ``solver="auto"`` a factor that would not fit selects CG.

    Raises
    ------
    ParameterError, TauOutOfRange, SolverError
    """
    run = Run(progress)
    run.emit("neighborhoods")
    problem = prepare(geometry, params, operator=operator, notes=run.notes)
    params, op, fixed, n_fixed = problem.params, problem.op, problem.fixed, problem.n_fixed
    run.frame = frame = problem.frame
    system, to_points = problem.system, problem.to_points
    geometry, run.data_weights = problem.geometry, problem.weights  # omega_i of the data term
    run.tau = resolve_tau(params, geometry, fixed, run, op, problem.weights)
    run.emit("analysis")
    automatic = params.tau_rule == "auto"
    if system.empty and automatic and run.tau:
        run.tau_how = (run.tau_how or "") + "; but nothing can move (all fixed or uncoupled)"
    if system.empty or (automatic and not run.tau):
        return _unchanged(geometry, params, op, run, n_fixed)
    if params.method == "windowed-sinc":
        return _filtered(geometry, params, op, run, system, to_points, fixed, n_fixed)
    dev = _deviation(system, params, memory_limit, run)
    try:
        if automatic:
            knee(dev, run)
        if params.tau_rule == "gcv":
            search = gcv_search(dev, geometry, params, fixed, run)
        else:
            search = find_lambda(dev, op, fixed, params, run)
    except TauOutOfRange as exc:
        if not automatic:
            raise
        run.tau_how = (run.tau_how or "") + (
            f"; this tau is not below phi(0) = {exc.tau_max:.6g}, the deviation of the fully "
            "smoothed shape: the estimated noise is as large as the shape"
        )
        run.tau = None
        return _unchanged(geometry, params, op, run, n_fixed)
    run.emit("postprocess", iteration=len(dev.history))
    U, search = _bounded(dev, search, params, run, system.size // max(int((~fixed).sum()), 1))
    X = geometry.points.copy()
    X[~fixed] = frame.back(to_points(U))
    if problem.weights is not None:  # outliers with no data weight: eq. (4) places them
        X = pull_in(X, op.L, problem.weights.pulled)
    X, along = relax_tangential(geometry, params, op, fixed, frame, X, search)
    volume_scale = None
    if params.preserve_volume:
        X, volume_scale = preserve_measure(geometry, X)
    if params.max_deviation is not None:
        X, _ = clip_points(geometry.points, X, params.max_deviation)
    return diagnostics(geometry, params, op, run, X, dev, search, n_fixed, volume_scale, along)


@dataclass(frozen=True)
class Problem:
    """Everything :func:`smooth` sets up before lambda (the opening every analysis shares).

    Attributes
    ----------
    geometry : Geometry
    params : SmoothingParams
        With ``displacement`` resolved (``"auto"`` replaced by the mode used).
    op : SmoothingOperator
        Neighbourhoods, weights, ``L`` (sections 2-4).
    fixed : ndarray of bool, shape (n,)
        Points eliminated from the system (section 8), see :func:`free_set`.
    n_fixed : int
        Points fixed by the input or ``fix_boundary``.
    frame : Frame
        The internal frame, weighted by the free points' ``omega``.
    system : SmoothingSystem
        Eq. (4) (or the normal-displacement system) in that frame.
    to_points : callable
        From the system's solution ``U`` to the free points (still in the frame).
    """

    geometry: Geometry
    params: SmoothingParams
    op: SmoothingOperator
    fixed: NDArray[np.bool_]
    n_fixed: int
    frame: Frame
    system: SmoothingSystem
    to_points: Callable[[Array], Array]
    weights: DataWeights | None = None


def prepare(
    geometry: Geometry,
    params: SmoothingParams,
    *,
    operator: SmoothingOperator | None = None,
    notes: list[str] | None = None,
) -> Problem:
    """Neighbourhoods and ``L`` -> free points -> the system of the selected mode.

    The opening of :func:`smooth`, shared by :func:`service.core.info.describe` and
    :func:`service.core.info.valid_range`. ``notes`` collects what the caller should be told
    (e.g. ``fix_boundary`` without a boundary).
    """
    requested = params.displacement
    params = resolve_displacement(params, geometry)
    op = _operator(geometry, params, operator)
    fixed, n_fixed = free_set(geometry, op, params, [] if notes is None else notes)
    geometry, weights = data_weights(geometry, params)  # robust and noise weights (issue 21)
    if weights is not None and notes is not None:
        notes.extend(weights.notes)
    frame = op.frame.weighted(geometry.omega()[~fixed])
    params, system, to_points = auto_system(
        params, requested, lambda p: smoothing_system(geometry, op, fixed, frame, p)
    )
    return Problem(geometry, params, op, fixed, n_fixed, frame, system, to_points, weights)


def _deviation(
    system: SmoothingSystem, params: SmoothingParams, memory_limit: int | None, run: Run
) -> Deviation:
    """phi(lambda) of ``system`` on the path :func:`choose_solver` picks, reporting to ``run``."""
    dev = Deviation(
        system,
        solver=choose_solver(system, params, memory_limit, run.notes),
        order=params.order,
        reuse=params.search != "rational",
        symbolic=analysis_of,
    )
    dev.listener = run.evaluated
    return dev


def _operator(
    geometry: Geometry, params: SmoothingParams, operator: SmoothingOperator | None
) -> SmoothingOperator:
    if operator is None:
        return build_operator(geometry, params)
    if operator.key != operator_key(geometry, params):
        raise ParameterError(
            "the operator was built for another geometry or other build parameters "
            "(laplacian, weights, neighborhood, k, sigma_h, sigma_f)",
            field="operator",
        )
    return operator


def free_set(
    geometry: Geometry, op: SmoothingOperator, params: SmoothingParams, notes: list[str]
) -> tuple[NDArray[np.bool_], int]:
    """Points eliminated from the system: fixed ones (section 8) and uncoupled ones.

    Returns
    -------
    fixed : ndarray of bool, shape (n,)
        Given fixed points, the boundary with ``fix_boundary``, and points without any
        coupling in ``L`` (they pass through bit-identical).
    n_fixed : int
        Points fixed by the input or ``fix_boundary``.
    """
    nb = op.neighborhoods
    fixed = geometry.fixed_mask()
    if params.fix_boundary:
        if nb.source == "knn":
            notes.append("fix_boundary has no effect on k-NN neighbourhoods (no boundary defined)")
        fixed = fixed | nb.boundary
    if params.preserve_volume:
        check_preservable(geometry, fixed)
    L = op.L
    coupled = (np.diff(L.indptr) > 0) | (np.bincount(L.indices, minlength=geometry.n) > 0)
    pinned = op.pinned if op.pinned is not None else False  # open-curve ends (issue 21)
    return fixed | ~coupled | pinned, int(fixed.sum())


def smoothing_system(
    geometry: Geometry,
    op: SmoothingOperator,
    fixed: NDArray[np.bool_],
    frame: Frame,
    params: SmoothingParams,
) -> tuple[SmoothingSystem, Callable[[Array], Array]]:
    """The system of the selected mode, in the internal frame (the mode dispatch point), and
    the map from its solution ``U`` to the free points.

    ``free`` displacement: eq. (4) with the fixed points eliminated
    (:func:`~service.core.system.elimination.laplacian_system`); ``normal``: one unknown per normal
    direction of each point (:func:`~service.core.system.displacement.normal_mode`).
    """
    P = frame.points(geometry.points)
    omega = geometry.omega() / frame.weight_scale
    if params.displacement == "normal":
        return normal_mode(geometry, op.L, op.neighborhoods, P, omega, fixed)
    return laplacian_system(op.L, P, omega, fixed), lambda U: U


def _bounded(
    dev: Deviation, search: LambdaSearch, params: SmoothingParams, run: Run, group: int
) -> tuple[Array, LambdaSearch]:
    """The solution ``U``; with ``max_deviation``, reweighted until every point is within it."""
    if params.max_deviation is None:
        return dev.solution(search.lam), search
    assert run.frame is not None
    frame = run.frame
    tau = None if run.tau is None or params.tau_rule == "gcv" else run.tau / frame.phi_factor
    hi = dev.system.lambda_ceiling(tau) if tau else search.lam
    res = bound_deviation(
        dev,
        params.max_deviation / frame.scale,
        search.lam,
        group=group,
        tau=tau,
        bracket=(dev.floor, max(hi, search.lam)),
        tolerance=params.tolerance,
    )
    run.notes.extend(res.warnings)
    run.bound = {
        "max_deviation": params.max_deviation,
        "rounds": res.rounds,
        "clipped": res.clipped,
    }
    history = [*search.history, *res.history]
    converged = tau is None or abs(res.phi - tau) <= params.tolerance * tau
    return dev.system.U0 + res.E, LambdaSearch(res.lam, res.phi, converged, history)


def _filtered(
    geometry: Geometry,
    params: SmoothingParams,
    op: SmoothingOperator,
    run: Run,
    system: SmoothingSystem,
    to_points: Callable[[Array], Array],
    fixed: NDArray[np.bool_],
    n_fixed: int,
) -> SmoothResult:
    """``method="windowed-sinc"`` (:func:`~service.core.search.polyfilter.filter_system`)."""
    assert run.frame is not None
    frame = run.frame
    dev = Deviation(system, solver="cg")  # products with M (counted), no solve
    tau = None if run.tau is None else run.tau / frame.phi_factor
    lam = None if params.lam is None else frame.lam_in(params.lam)
    bound = system.phi0 if system.phi0 is not None else system.phi0_bound
    if tau is not None and bound is not None and tau >= bound:
        check_range(dev, op, fixed, params, run)
    U, search = filter_system(dev, params.laplacian, tau, lam, params.tolerance)
    if not search.converged:
        run.notes.append("windowed-sinc: no pass band of this degree meets tau within tolerance")
    run.evaluated(search.lam, search.phi, 1)
    X = geometry.points.copy()
    X[~fixed] = frame.back(to_points(U))
    return diagnostics(geometry, params, op, run, X, dev, search, n_fixed)


def _unchanged(
    geometry: Geometry, params: SmoothingParams, op: SmoothingOperator, run: Run, n_fixed: int
) -> SmoothResult:
    """Nothing to do: every point fixed, a zero Laplacian, or an automatic tau that finds no
    noise or no valid budget (the reason is in ``tau_how`` and the notes)."""
    if params.tau_rule == "auto":
        run.notes.append(
            "not smoothed: " + (run.tau_how or "nothing can move").removeprefix("automatic: ")
        )
        run.tau = None
    elif run.tau is not None:
        raise TauOutOfRange(
            "nothing can move (every point is fixed or uncoupled): no smoothing factor can be "
            "met; valid range is empty",
            field="params.tau" if params.tau is not None else "params.rms",
            tau=run.tau,
            tau_max=0.0,
        )
    else:
        run.notes.append("nothing to smooth: the input is returned unchanged")
    search = LambdaSearch(float(params.lam or 0.0), 0.0, True, [])
    return diagnostics(geometry, params, op, run, geometry.points.copy(), None, search, n_fixed)
