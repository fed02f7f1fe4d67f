"""``smooth()``: the single entry point of the engine (exported as ``service.core.smooth``).

Pipeline (report sections 4-8): neighbourhoods and the Laplacian (:mod:`.operator`) -> the free
points (fixed ones eliminated, section 8) -> the smoothing system (:mod:`.system`) -> lambda
(given, or searched so that ``phi(lambda) = tau``, :mod:`.tau`) -> the points ``X`` -> optional
volume/area rescaling -> diagnostics. Everything between the operator and ``X`` runs in the
internal frame of :mod:`.frame`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from service.core import cache
from service.core.autotau import auto_tau, gcv_lambda, knee_tau
from service.core.displacement import auto_system, normal_mode, resolve_displacement
from service.core.elimination import laplacian_system, phi_at_zero
from service.core.errors import ParameterError, SolverError, TauOutOfRange
from service.core.frame import Frame
from service.core.geometry import Geometry
from service.core.guards import guard_warnings, noise_ratio, shape_checks
from service.core.maxnorm import bound_deviation, clip_points
from service.core.operator import (
    SmoothingOperator,
    build_laplacian,
    build_operator,
    operator_key,
)
from service.core.params import SmoothingParams
from service.core.polyfilter import filter_system
from service.core.progress import ProgressCallback, ProgressEvent
from service.core.resources import choose_solver, prefer_matrix_free
from service.core.result import SmoothResult, Spectrum
from service.core.shrinkage import check_preservable, preserve_measure
from service.core.spectrum import SPECTRUM_MAX_POINTS, filter_factors, singular_values
from service.core.system import Deviation, SmoothingSystem
from service.core.tau import (
    LambdaSearch,
    estimate_lambda,
    initial_lambda,
    newton_search,
    search_lambda,
)

__all__ = ["ProgressCallback", "build_laplacian", "build_operator", "smooth"]

Array = NDArray[np.float64]


class Run:
    """Clock, progress events and notes of one :func:`smooth` call (input-frame numbers)."""

    def __init__(self, progress: ProgressCallback | None, frame: Frame | None = None) -> None:
        self.t0 = time.perf_counter()
        self.progress = progress
        self.tau: float | None = None
        self.frame = frame
        self.notes: list[str] = []
        self.search_seconds = 0.0
        self.sigma: float | None = None  # core-quality: automatic tau, max-norm bound
        self.tau_how: str | None = None
        self.bound: dict[str, Any] | None = None

    def emit(self, stage: str, **kw: Any) -> None:
        if self.progress is not None:
            elapsed = time.perf_counter() - self.t0
            self.progress(ProgressEvent(stage, tau=self.tau, elapsed=elapsed, **kw))

    def evaluated(self, lam: float, phi: float, iteration: int) -> None:
        """One ``search`` event per lambda tried (internal numbers converted)."""
        assert self.frame is not None
        f = self.frame
        self.emit("search", iteration=iteration, lam=f.lam_out(lam), phi=phi * f.phi_factor)


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
    requested = params.displacement
    params = resolve_displacement(params, geometry)
    run.emit("neighborhoods")
    op = _operator(geometry, params, operator)
    fixed, n_fixed = free_set(geometry, op, params, run.notes)
    run.frame = frame = op.frame.weighted(geometry.omega()[~fixed])
    params, system, to_points = auto_system(
        params, requested, lambda p: smoothing_system(geometry, op, fixed, frame, p)
    )
    run.tau = resolve_tau(params, geometry, fixed, run, op)
    run.emit("analysis")
    if system.empty:
        return _unchanged(geometry, params, op, run, n_fixed)
    if params.method == "windowed-sinc":
        return _filtered(geometry, params, op, run, system, to_points, fixed, n_fixed)
    dev = _deviation(system, params, memory_limit, run)
    if params.tau_rule == "auto" and run.tau:
        _knee(dev, run)
    if params.tau_rule == "gcv":
        search = _gcv(dev, geometry, params, fixed, run)
    else:
        search = find_lambda(dev, op, fixed, params, run)
    run.emit("postprocess", iteration=len(dev.history))
    U, search = _bounded(dev, search, params, run, system.size // max(int((~fixed).sum()), 1))
    X = geometry.points.copy()
    X[~fixed] = frame.back(to_points(U))
    volume_scale = None
    if params.preserve_volume:
        X, volume_scale = preserve_measure(geometry, X)
    if params.max_deviation is not None:
        X, _ = clip_points(geometry.points, X, params.max_deviation)
    return diagnostics(geometry, params, op, run, X, dev, search, n_fixed, volume_scale)


def _deviation(
    system: SmoothingSystem, params: SmoothingParams, memory_limit: int | None, run: Run
) -> Deviation:
    """phi(lambda) of ``system`` on the path :func:`choose_solver` picks, reporting to ``run``."""
    dev = Deviation(
        system,
        solver=choose_solver(system, params, memory_limit, run.notes),
        order=params.order,
        reuse=params.search != "rational",
        symbolic=cache.analysis_of,
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
    return fixed | ~coupled, int(fixed.sum())


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
    (:func:`~service.core.elimination.laplacian_system`); ``normal``: one unknown per normal
    direction of each point (:func:`~service.core.displacement.normal_mode`).
    """
    P = frame.points(geometry.points)
    omega = geometry.omega() / frame.weight_scale
    if params.displacement == "normal":
        return normal_mode(geometry, op.L, op.neighborhoods, P, omega, fixed)
    return laplacian_system(op.L, P, omega, fixed), lambda U: U


def resolve_tau(
    params: SmoothingParams,
    geometry: Geometry,
    fixed: NDArray[np.bool_],
    run: Run,
    op: SmoothingOperator | None = None,
) -> float | None:
    """The target ``tau`` in the input's frame: given, ``rms^2 sum omega_i^2`` (free points),
    or from the estimated noise (:func:`~service.core.autotau.auto_tau`); ``None`` for a given
    lambda and for ``tau="gcv"`` (known once lambda is).
    """
    rule = params.tau_rule
    if rule in ("lam", "gcv"):
        return None
    if rule == "auto":
        adjacency = op.neighborhoods.adjacency if op is not None else None
        auto = auto_tau(geometry, params, fixed, adjacency)
        run.sigma, run.tau_how = auto.sigma, auto.rule
        return auto.tau
    if rule == "tau":
        return float(params.tau)  # type: ignore[arg-type]
    assert params.rms is not None
    return float(params.rms**2 * np.sum(geometry.omega()[~fixed] ** 2))


def _out_of_range(params: SmoothingParams, tau: float, phi0: float) -> TauOutOfRange:
    return TauOutOfRange(
        f"smoothing factor tau={tau:.6g} is out of range: it must lie in (0, {phi0:.6g}),"
        " where the upper bound phi(0) is the deviation of the fully smoothed shape",
        field="params.tau" if params.tau is not None else "params.rms",
        tau=tau,
        tau_max=phi0,
    )


def find_lambda(
    dev: Deviation,
    op: SmoothingOperator,
    fixed: NDArray[np.bool_],
    params: SmoothingParams,
    run: Run,
) -> LambdaSearch:
    """lambda (internal frame): given, or the root of ``phi(lambda) = tau`` (section 6)."""
    t0 = time.perf_counter()
    try:
        return _find_lambda(dev, op, fixed, params, run)
    finally:
        run.search_seconds = time.perf_counter() - t0


def _find_lambda(
    dev: Deviation,
    op: SmoothingOperator,
    fixed: NDArray[np.bool_],
    params: SmoothingParams,
    run: Run,
) -> LambdaSearch:
    assert run.frame is not None
    frame = run.frame
    if params.lam is not None:
        lam = frame.lam_in(params.lam)
        return LambdaSearch(lam, dev(lam), True, list(dev.history))
    assert run.tau is not None
    tau, system = run.tau / frame.phi_factor, dev.system
    phi0 = system.phi0
    bound = system.phi0_bound if system.phi0_bound is not None else np.inf
    if params.search == "rational" or (phi0 is None and tau >= bound):
        phi0 = phi_at_zero_of(dev, op, fixed, params)
    if phi0 is not None and not 0.0 < tau < phi0:
        raise _out_of_range(params, run.tau, phi0 * frame.phi_factor)
    if params.search == "rational":
        assert phi0 is not None
        lam0 = initial_lambda(_fro(system.explicit()), float(np.linalg.norm(system.d2)))
        return search_lambda(dev, tau, phi0, lam0, params.tolerance, params.max_iterations)
    lo, hi = dev.floor, max(system.lambda_ceiling(tau), dev.floor)
    inv_d = 1.0 / np.sqrt(system.d2)[:, None]
    lam0, _, _, _ = estimate_lambda(
        lambda V: inv_d * dev.solver.matvec(inv_d * V),
        inv_d * system.r,
        tau,
        lo,
        hi,
        order=dev.order,
    )
    if params.solver == "auto" and prefer_matrix_free(system.size, lam0, system.mu_bound()):
        dev.use_matrix_free()
        run.notes.append(
            "matrix-free path: conjugate gradients are cheaper at this size and lambda"
        )
    search = newton_search(
        dev,
        dev.derivative,
        tau,
        lam0,
        lo,
        hi,
        order=dev.order,
        tolerance=params.tolerance,
        max_iterations=params.max_iterations,
        propose=dev.local_root if params.search == "auto" else None,
        below=lambda: _check_range(dev, op, fixed, params, run),
    )
    if not search.converged and search.phi < tau:
        _check_range(dev, op, fixed, params, run)
    return search


def _check_range(
    dev: Deviation,
    op: SmoothingOperator,
    fixed: NDArray[np.bool_],
    params: SmoothingParams,
    run: Run,
) -> None:
    """Raise :class:`TauOutOfRange` unless ``tau < phi(0)`` (exact ``phi(0)``)."""
    assert run.frame is not None and run.tau is not None
    phi0 = phi_at_zero_of(dev, op, fixed, params)
    if run.tau / run.frame.phi_factor >= phi0:
        raise _out_of_range(params, run.tau, phi0 * run.frame.phi_factor)


def phi_at_zero_of(
    dev: Deviation, op: SmoothingOperator, fixed: NDArray[np.bool_], params: SmoothingParams
) -> float:
    """``phi(0)``: eqs. (13-14) for free displacement, the system's limit otherwise."""
    return phi_at_zero(dev, op.L, fixed) if params.displacement == "free" else dev.phi0()


def _gcv(
    dev: Deviation, geometry: Geometry, params: SmoothingParams, fixed: NDArray[np.bool_], run: Run
) -> LambdaSearch:
    """``tau="gcv"``: lambda by generalized cross-validation (started at the Lanczos estimate
    of the automatic tau's lambda, no factorization); tau is phi there."""
    assert run.frame is not None
    system = dev.system
    lo = dev.floor
    start = None
    try:
        tau0 = auto_tau(geometry, params, fixed).tau / run.frame.phi_factor
        if tau0 > 0:
            hi = max(system.lambda_ceiling(tau0), lo)
            inv_d = 1.0 / np.sqrt(system.d2)[:, None]
            start, _, _, _ = estimate_lambda(
                lambda V: inv_d * dev.solver.matvec(inv_d * V), inv_d * system.r, tau0, lo, hi,
                order=dev.order,
            )
    except ParameterError:  # no noise estimate: start from the middle of the range
        pass
    scale = float(np.sum(system.r**2 / system.d2[:, None]))  # ||D^-1 r||^2 >= phi(lambda) lambda^2
    hi = max(system.lambda_ceiling(1e-12 * scale), lo) if scale > 0 else lo
    lam = gcv_lambda(dev, lo, hi, start if start else math.sqrt(lo * hi))
    phi = dev(lam)
    run.tau = phi * run.frame.phi_factor
    run.tau_how = f"generalized cross-validation (trace of I - H by probes, order {dev.order})"
    return LambdaSearch(lam, phi, True, list(dev.history))


def _knee(dev: Deviation, run: Run) -> None:
    """Automatic tau: move the discrepancy estimate to the knee of ``phi(lambda)`` near it."""
    assert run.frame is not None and run.tau is not None
    tau = knee_tau(dev, run.tau / run.frame.phi_factor)
    if tau is None:
        run.tau_how = (run.tau_how or "") + "; no knee of phi(lambda) near it: used as is"
        return
    run.tau_how = (run.tau_how or "") + (
        f"; moved to the knee of phi(lambda) at tau = {tau * run.frame.phi_factor:.6g} "
        f"({tau * run.frame.phi_factor / run.tau:.3g} x)"
    )
    run.tau = tau * run.frame.phi_factor


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
        dev, params.max_deviation / frame.scale, search.lam, group=group, tau=tau,
        bracket=(dev.floor, max(hi, search.lam)), tolerance=params.tolerance,
    )
    run.notes.extend(res.warnings)
    run.bound = {"max_deviation": params.max_deviation, "rounds": res.rounds,
                 "clipped": res.clipped}
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
    """``method="windowed-sinc"`` (:func:`~service.core.polyfilter.filter_system`)."""
    assert run.frame is not None
    frame = run.frame
    dev = Deviation(system, solver="cg")  # products with M (counted), no solve
    tau = None if run.tau is None else run.tau / frame.phi_factor
    lam = None if params.lam is None else frame.lam_in(params.lam)
    bound = system.phi0 if system.phi0 is not None else system.phi0_bound
    if tau is not None and bound is not None and tau >= bound:
        _check_range(dev, op, fixed, params, run)
    U, search = filter_system(dev, params.laplacian, tau, lam, params.tolerance)
    if not search.converged:
        run.notes.append("windowed-sinc: no pass band of this degree meets tau within tolerance")
    run.evaluated(search.lam, search.phi, 1)
    X = geometry.points.copy()
    X[~fixed] = frame.back(to_points(U))
    return diagnostics(geometry, params, op, run, X, dev, search, n_fixed)


def _fro(M: sp.spmatrix) -> float:
    return float(np.sqrt(np.sum(np.asarray(M.data) ** 2)))


def _unchanged(
    geometry: Geometry, params: SmoothingParams, op: SmoothingOperator, run: Run, n_fixed: int
) -> SmoothResult:
    """Nothing can move (every point fixed, or a zero Laplacian)."""
    if run.tau is not None:
        raise TauOutOfRange(
            "nothing can move (every point is fixed or uncoupled): no smoothing factor can be "
            "met; valid range is empty",
            field="params.tau" if params.tau is not None else "params.rms",
            tau=run.tau,
            tau_max=0.0,
        )
    run.notes.append("nothing to smooth: the input is returned unchanged")
    search = LambdaSearch(float(params.lam or 0.0), 0.0, True, [])
    return diagnostics(geometry, params, op, run, geometry.points.copy(), None, search, n_fixed)


def diagnostics(
    geometry: Geometry,
    params: SmoothingParams,
    op: SmoothingOperator,
    run: Run,
    X: Array,
    dev: Deviation | None,
    search: LambdaSearch,
    n_fixed: int,
    volume_scale: float | None = None,
) -> SmoothResult:
    """The :class:`SmoothResult` of a run: input-frame numbers, timings and work counters."""
    frame = run.frame if run.frame is not None else op.frame
    moved = X - geometry.points
    dev_pt = np.linalg.norm(moved, axis=1)
    # phi of the solution (before any volume rescaling), as recorded in the history
    phi = search.phi * frame.phi_factor if dev is not None else 0.0
    if not (np.isfinite(phi) and np.isfinite(search.lam) and np.isfinite(X).all()):
        raise SolverError(  # never report a non-finite number (issue 15)
            "the solution is not finite at this scale (lambda, phi or the points overflowed)",
            field="params",
        )
    stats = dev.stats if dev is not None else None
    timings = dict(op.timings)
    if stats is not None:
        timings.update(
            analysis=stats.analysis,
            factorization=stats.factorization,
            solve=stats.solve,
            matvec=stats.matvec,
        )
    checks = shape_checks(geometry, X)
    ratio = lambda: noise_ratio(geometry, run.sigma)  # noqa: E731 (only called when needed)
    run.notes.extend(guard_warnings(checks, params.tau_rule, ratio))
    timings["search"] = run.search_seconds
    timings["total"] = time.perf_counter() - run.t0
    tau = run.tau
    spectrum = None
    if params.spectrum:
        spectrum = _spectrum(op, geometry, frame, search.lam, n_fixed, run.notes)
    return SmoothResult(
        points=X,
        lam=params.lam if params.lam is not None else frame.lam_out(search.lam),
        phi=phi,
        tau=tau,
        relative_error=None if tau is None else abs(phi - tau) / tau,
        converged=search.converged,
        iterations=len(search.history),
        factorizations=stats.factorizations if stats else 0,
        solves=stats.solves if stats else 0,
        matvecs=stats.matvecs if stats else 0,
        history=[(frame.lam_out(lam), p * frame.phi_factor) for lam, p in search.history],
        deviation=dev_pt,
        rms_deviation=float(np.sqrt(np.mean(dev_pt**2))),
        max_deviation=float(dev_pt.max()),
        timings=timings,
        solver=dev.solver.name if dev is not None and params.method == "tikhonov" else "none",
        method=params.method,
        search="none" if params.lam is not None else params.search,
        order=params.order,
        laplacian=params.laplacian,
        weights=op.scheme,
        kind=geometry.kind,
        n_fixed=n_fixed,
        volume_scale=volume_scale,
        warnings=[*run.notes, *(stats.warnings if stats else [])],
        spectrum=spectrum,
        displacement=params.displacement,
        tau_rule=params.tau_rule,
        sigma_estimate=run.sigma,
        tau_how=run.tau_how,
        checks=checks.to_dict(),
        bound=run.bound,
    )


def _spectrum(
    op: SmoothingOperator,
    geometry: Geometry,
    frame: Frame,
    lam: float,
    n_fixed: int,
    notes: list[str],
) -> Spectrum | None:
    if n_fixed:
        notes.append("spectrum: not available with fixed points (eq. 12 assumes none)")
        return None
    if geometry.n > SPECTRUM_MAX_POINTS:
        notes.append(f"spectrum: only computed for inputs up to {SPECTRUM_MAX_POINTS} points")
        return None
    L = op.L * op.frame.scale ** (-op.frame.power)
    sigma, _ = singular_values(L, geometry.omega())
    return Spectrum(sigma=sigma, gamma=filter_factors(sigma, frame.lam_out(lam)))
