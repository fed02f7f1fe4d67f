"""The target and lambda of a run: ``tau`` resolved once (given, from ``rms``, automatic or by
GCV), its valid range ``(0, phi(0))`` (eqs. 13-14) and the lambda search that meets it
(section 6; :mod:`.tau` holds the search algorithms themselves).
"""

from __future__ import annotations

import math
import time

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from service.core.errors import ParameterError, TauOutOfRange
from service.core.geometry import Geometry
from service.core.linalg.resources import prefer_matrix_free
from service.core.noise.robust import DataWeights
from service.core.operator.build import SmoothingOperator
from service.core.params import SmoothingParams
from service.core.run import Run
from service.core.search.autotau import auto_tau, gcv_lambda, knee_tau
from service.core.search.budget import free_weight, rms_to_tau
from service.core.search.roots import (
    LambdaSearch,
    estimate_lambda,
    initial_lambda,
    newton_search,
    search_lambda,
)
from service.core.system.deviation import Deviation
from service.core.system.elimination import phi_at_zero

__all__ = ["check_range", "find_lambda", "gcv_search", "knee", "phi_at_zero_of", "resolve_tau"]


def resolve_tau(
    params: SmoothingParams,
    geometry: Geometry,
    fixed: NDArray[np.bool_],
    run: Run,
    op: SmoothingOperator | None = None,
    weights: DataWeights | None = None,
) -> float | None:
    """The target ``tau`` in the input's frame: given, ``rms^2 sum omega_i^2`` (free points),
    or from the estimated noise (:func:`~service.core.search.autotau.auto_tau`); ``None`` for a
    given
    lambda and for ``tau="gcv"`` (known once lambda is).
    """
    rule = params.tau_rule
    if rule in ("lam", "gcv"):
        return None
    if rule == "auto":
        adjacency = op.neighborhoods.adjacency if op is not None else None
        scale = None if weights is None else weights.tau_scale
        auto = auto_tau(geometry, params, fixed, adjacency, scale)
        run.sigma, run.tau_how = auto.sigma, auto.rule
        return auto.tau
    if rule == "tau":
        return float(params.tau)  # type: ignore[arg-type]
    assert params.rms is not None
    return rms_to_tau(params.rms, free_weight(geometry, fixed))


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
    lam0 = lanczos_lambda(dev, tau, lo, hi)
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
        below=lambda: check_range(dev, op, fixed, params, run),
    )
    if not search.converged and search.phi < tau:
        check_range(dev, op, fixed, params, run)
    return search


def lanczos_lambda(dev: Deviation, tau: float, lo: float, hi: float) -> float:
    """The lambda of ``phi(lambda) = tau`` in ``[lo, hi]`` from Lanczos quadrature on
    ``D^-1 M D^-1`` and ``D^-1 r`` (matrix products only, no factorization)."""
    system = dev.system
    inv_d = 1.0 / np.sqrt(system.d2)[:, None]
    lam, _, _, _ = estimate_lambda(
        lambda V: inv_d * dev.solver.matvec(inv_d * V), inv_d * system.r, tau, lo, hi,
        order=dev.order,
    )
    return float(lam)


def check_range(
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


def gcv_search(
    dev: Deviation, geometry: Geometry, params: SmoothingParams, fixed: NDArray[np.bool_], run: Run
) -> LambdaSearch:
    """``tau="gcv"``: lambda by generalized cross-validation (started at the Lanczos estimate
    of the automatic tau's lambda, no factorization); tau is phi there."""
    assert run.frame is not None
    system = dev.system
    lo = dev.floor
    start = None
    try:
        tau0 = auto_tau(geometry, params, fixed).rough_tau / run.frame.phi_factor
        if tau0 > 0:
            start = lanczos_lambda(dev, tau0, lo, max(system.lambda_ceiling(tau0), lo))
    except ParameterError:  # no noise estimate: start from the middle of the range
        pass
    scale = float(np.sum(system.r**2 / system.d2[:, None]))  # ||D^-1 r||^2 >= phi(lambda) lambda^2
    hi = max(system.lambda_ceiling(1e-12 * scale), lo) if scale > 0 else lo
    lam = gcv_lambda(dev, lo, hi, start if start else math.sqrt(lo * hi))
    phi = dev(lam)
    run.tau = phi * run.frame.phi_factor
    run.tau_how = f"generalized cross-validation (trace of I - H by probes, order {dev.order})"
    return LambdaSearch(lam, phi, True, list(dev.history))


def knee(dev: Deviation, run: Run) -> None:
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


def _fro(M: sp.spmatrix) -> float:
    return float(np.sqrt(np.sum(np.asarray(M.data) ** 2)))
