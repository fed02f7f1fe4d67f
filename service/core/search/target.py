"""The target and lambda of a run: ``tau`` resolved once (given, from ``rms``, automatic or by
GCV), its valid range ``(0, phi(0))`` (eqs. 13-14) and the lambda search that meets it
(section 6; :mod:`service.core.search.roots` holds the search algorithms themselves).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from service.core.errors import ParameterError, TauOutOfRange
from service.core.frame import Frame
from service.core.geometry import Geometry
from service.core.linalg.resources import prefer_matrix_free
from service.core.noise.robust import DataWeights
from service.core.operator.build import SmoothingOperator
from service.core.params import SmoothingParams
from service.core.search.autotau import auto_tau, gcv_lambda
from service.core.search.budget import free_weight, rms_to_tau
from service.core.search.roots import (
    LambdaSearch,
    estimate_lambda,
    initial_lambda,
    newton_search,
    search_lambda,
    unresolved_below,
)
from service.core.system.deviation import Deviation
from service.core.system.elimination import phi_at_zero

__all__ = [
    "Solution",
    "Target",
    "check_range",
    "find_lambda",
    "gcv_search",
    "out_of_range",
    "phi_at_zero_of",
    "resolve_tau",
]


@dataclass(frozen=True)
class Target:
    """The target of a run (input frame), resolved once; the automatic rule and GCV return
    new ones.

    Attributes
    ----------
    tau : float or None
        ``tau`` of eq. (3): the budget ``phi(lambda) = ||D (X - P)||_F^2`` (eq. 15) must meet;
        ``None`` for a given lambda (and for ``tau="gcv"`` until lambda is known).
    how : str or None
        How the automatic tau (or GCV) chose it, in words (the report's ``tau_how``).
    sigma : float or None
        The automatic rule's noise level (0 when no noise was found): the local fits'
        estimate, then the larger of it and Wahba's once the rule decided lambda.
    evidence : dict or None
        The automatic rule's evidence (:meth:`~service.core.search.risk_rule.RiskChoice.evidence`,
        input frame).
    """

    tau: float | None
    how: str | None = None
    sigma: float | None = None
    evidence: dict[str, Any] | None = None

    def noted(self, text: str) -> Target:
        """This target with ``text`` appended to :attr:`how`."""
        return replace(self, how=(self.how or "") + text)


@dataclass(frozen=True)
class Solution:
    """What the solve stage returns (:func:`service.core.pipeline.solve`).

    Attributes
    ----------
    target : Target
        The target the run met (set by the automatic rule or GCV: phi at their lambda).
    search : LambdaSearch
        lambda, phi (internal frame), convergence and every ``(lambda, phi)`` tried.
    U : ndarray or None
        The system's solution at ``search.lam`` (``None``: nothing was solved).
    dev : Deviation or None
        ``phi(lambda)`` with its solver and work counters.
    bound : dict or None
        The max-norm bound's record (section 9): ``max_deviation``, ``rounds``, ``clipped``.
    seconds : float
        Time spent in the lambda search.
    """

    target: Target
    search: LambdaSearch
    U: NDArray[np.float64] | None = None
    dev: Deviation | None = None
    bound: dict[str, Any] | None = None
    seconds: float = 0.0


def resolve_tau(
    params: SmoothingParams,
    geometry: Geometry,
    fixed: NDArray[np.bool_],
    op: SmoothingOperator | None = None,
    weights: DataWeights | None = None,
) -> Target:
    """The target in the input's frame: given ``tau``, ``rms^2 sum omega_i^2`` (free points,
    eq. 3), or from the estimated noise (:func:`~service.core.search.autotau.auto_tau`);
    ``tau=None`` for a given lambda and for ``tau="gcv"`` (known once lambda is).
    """
    rule = params.tau_rule
    if rule in ("lam", "gcv"):
        return Target(None)
    if rule == "auto":
        adjacency = op.neighborhoods.adjacency if op is not None else None
        scale = None if weights is None else weights.tau_scale
        auto = auto_tau(geometry, params, fixed, adjacency, scale)
        return Target(auto.tau, auto.rule, auto.sigma)
    if rule == "tau":
        return Target(float(params.tau))  # type: ignore[arg-type]
    assert params.rms is not None
    return Target(rms_to_tau(params.rms, free_weight(geometry, fixed)))


def out_of_range(params: SmoothingParams, tau: float, phi0: float) -> TauOutOfRange:
    """The error of a given tau (or rms) not below ``phi(0)`` (input frame)."""
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
    target: Target,
    frame: Frame,
    notes: list[str],
) -> LambdaSearch:
    """lambda (internal frame): given, or the root of ``phi(lambda) = tau`` (section 6.3).

    Raises
    ------
    TauOutOfRange
        ``tau`` not in ``(0, phi(0))`` (eqs. 13-14).
    """
    if params.lam is not None:
        lam = frame.lam_in(params.lam)
        return LambdaSearch(lam, dev(lam), True, list(dev.history))
    assert target.tau is not None
    tau, system = frame.tau_in(target.tau), dev.system
    phi0 = system.phi0
    bound = system.phi0_bound if system.phi0_bound is not None else np.inf
    if params.search == "rational" or (phi0 is None and tau >= bound):
        phi0 = phi_at_zero_of(dev, op, fixed, params)
    if phi0 is not None and not 0.0 < tau < phi0:
        raise out_of_range(params, target.tau, frame.phi_out(phi0))
    if params.search == "rational":
        assert phi0 is not None
        lam0 = initial_lambda(_fro(system.explicit()), float(np.linalg.norm(system.d2)))
        return search_lambda(dev, tau, phi0, lam0, params.tolerance, params.max_iterations)
    lo, hi = dev.floor, max(system.lambda_ceiling(tau), dev.floor)
    lam0 = lanczos_lambda(dev, tau, lo, hi)
    if params.solver == "auto" and prefer_matrix_free(system.size, lam0, system.mu_bound()):
        dev.use_matrix_free()
        notes.append("matrix-free path: conjugate gradients are cheaper at this size and lambda")
    in_range = lambda: check_range(dev, op, fixed, params, target, frame)  # noqa: E731
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
        below=in_range,
    )
    if not search.converged and search.phi < tau:
        in_range()
    unresolved = None if search.converged else unresolved_below(search.history)
    if unresolved is not None:
        notes.append(
            f"tau is not met (phi = {frame.phi_out(search.phi):.4g}, relative error "
            f"{abs(search.phi - tau) / tau:.2g}): it needs a lambda so small (about "
            f"{frame.lam_out(search.lam):.3g}) that the solve's rounding swamps phi, which no "
            "longer falls as lambda grows; give a smaller tau or rms"
        )
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
    target: Target,
    frame: Frame,
) -> None:
    """Raise :class:`TauOutOfRange` unless ``tau < phi(0)`` (exact ``phi(0)``, eqs. 13-14)."""
    assert target.tau is not None
    phi0 = phi_at_zero_of(dev, op, fixed, params)
    if frame.tau_in(target.tau) >= phi0:
        raise out_of_range(params, target.tau, frame.phi_out(phi0))


def phi_at_zero_of(
    dev: Deviation, op: SmoothingOperator, fixed: NDArray[np.bool_], params: SmoothingParams
) -> float:
    """``phi(0)``: eqs. (13-14) for free displacement, the system's limit otherwise."""
    return phi_at_zero(dev, op.L, fixed) if params.displacement == "free" else dev.phi0()


def gcv_search(
    dev: Deviation,
    geometry: Geometry,
    params: SmoothingParams,
    fixed: NDArray[np.bool_],
    frame: Frame,
) -> tuple[LambdaSearch, Target]:
    """``tau="gcv"``: lambda by generalized cross-validation (started at the Lanczos estimate
    of the automatic tau's lambda, no factorization); the target is phi there."""
    system = dev.system
    lo = dev.floor
    start = None
    try:
        tau0 = frame.tau_in(auto_tau(geometry, params, fixed).rough_tau)
        if tau0 > 0:
            start = lanczos_lambda(dev, tau0, lo, max(system.lambda_ceiling(tau0), lo))
    except ParameterError:  # no noise estimate: start from the middle of the range
        pass
    scale = float(np.sum(system.r**2 / system.d2[:, None]))  # ||D^-1 r||^2 >= phi(lambda) lambda^2
    hi = max(system.lambda_ceiling(1e-12 * scale), lo) if scale > 0 else lo
    lam = gcv_lambda(dev, lo, hi, start if start else math.sqrt(lo * hi))
    phi = dev(lam)
    how = f"generalized cross-validation (trace of I - H by probes, order {dev.order})"
    return LambdaSearch(lam, phi, True, list(dev.history)), Target(frame.phi_out(phi), how)


def _fro(M: sp.spmatrix) -> float:
    return float(np.sqrt(np.sum(np.asarray(M.data) ** 2)))
