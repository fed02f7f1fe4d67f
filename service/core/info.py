"""``describe()``: what an input is and which smoothing factors make sense, without smoothing.

Used by ``geosmooth info``, the API's ``POST /v1/info`` and the web page. It builds the
neighbourhoods and the Laplacian once (as ``smooth`` would) to get ``phi(0)`` of eq. (14), the
upper end of the valid range of ``tau`` (section 6.1), and estimates the noise level (see
:mod:`service.core.noise.estimate`) to suggest a smoothing factor.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import NDArray

from service.core.errors import ParameterError
from service.core.geometry import Geometry, mean_spacing
from service.core.params import SmoothingParams
from service.core.search.budget import free_weight, tau_to_rms

if TYPE_CHECKING:
    from service.core.problem import Problem

__all__ = ["describe", "mean_spacing", "valid_range"]


def _bbox(P: NDArray[np.float64]) -> dict[str, list[float]]:
    return {"min": P.min(axis=0).tolist(), "max": P.max(axis=0).tolist()}


def _phi0(geometry: Geometry, params: SmoothingParams) -> tuple[float, float, int, Problem]:
    """``phi(0)`` of the mode ``params`` selects (eq. 14 per component for free displacement,
    fixed points as boundary values; the system's limit for normal displacement), the weight
    sum ``sum omega_i^2`` over the points that can move, the number of neighbour pairs and
    the problem :func:`~service.core.pipeline.plan_and_prepare` set up (as ``smooth`` would)."""
    import scipy.sparse as sp

    from service.core.pipeline import plan_and_prepare
    from service.core.search.target import phi_at_zero_of
    from service.core.system.deviation import Deviation

    _, problem = plan_and_prepare(geometry, params)
    adj = problem.op.neighborhoods.adjacency
    n_edges = int(sp.triu(adj + adj.T, k=1).nnz)
    fixed = problem.fixed
    if fixed.all():
        return 0.0, 0.0, n_edges, problem
    phi0 = problem.system.phi0
    if phi0 is None:
        phi0 = phi_at_zero_of(
            Deviation(problem.system, solver=_solver(problem.params)), problem.op, fixed,
            problem.params,
        )  # fmt: skip
    w2 = free_weight(geometry, fixed)
    return problem.phi_out(float(phi0)), w2, n_edges, problem


def _solver(params: SmoothingParams) -> Literal["cholmod", "superlu"]:
    return "superlu" if params.solver == "superlu" else "cholmod"


def valid_range(geometry: Geometry, params: SmoothingParams) -> tuple[float, float]:
    """``(phi(0), sum omega_i^2 over the points that can move)`` for ``params``' mode: the
    valid ``tau`` lie in ``(0, phi(0))``, the valid ``rms`` in ``(0, tau_to_rms(phi(0), sum))``.

    What :func:`describe` reports as ``tau_range`` / ``rms_range``, without its noise estimate
    (the API's check of a given ``tau`` at submit).
    """
    phi0, weight_sum, *_ = _phi0(geometry, params)
    return phi0, weight_sum


def _automatic(problem: Problem, tau0: float, sigma: float) -> tuple[float, float, str]:
    """The tau the automatic rule would meet (:mod:`~service.core.search.risk_rule`: phi at
    lambda*, by the rule's recurrence with no solve) and its words."""
    from service.core.pipeline import noise_model
    from service.core.search.one_run_target import ONE_RUN_FROM, choose
    from service.core.search.target import Target
    from service.core.system.deviation import Deviation

    params, frame = problem.params, problem.frame
    dev = Deviation(problem.system, solver=_solver(params), order=params.order)
    small = problem.system.size < ONE_RUN_FROM
    choice = choose(dev, noise_model(problem, Target(tau0, sigma=sigma)), refine=small)
    tau = frame.phi_out(choice.phi)
    used = math.sqrt(choice.sigma2) * frame.scale
    return tau, used, (f"; the automatic rule: lambda = {frame.lam_out(choice.lam):.6g} "
                       f"minimises the unbiased predictive risk with sigma = {used:.6g}, the "
                       f"larger of the local fits' and Wahba's: tau = {tau:.6g}")


def _risk(problem: Problem) -> bool:
    """Whether the automatic rule is the risk estimate (not a track's discrepancy budget)."""
    from service.core.problem import is_track

    return not is_track(problem.geometry, problem.params.tau_rule)


def describe(geometry: Geometry, params: SmoothingParams | None = None) -> dict[str, Any]:
    """JSON-ready description of ``geometry`` and of the smoothing factors it admits.

    Parameters
    ----------
    geometry : Geometry
    params : SmoothingParams, optional
        Neighbourhood, weight and fixed-point settings to analyse with (``tau``/``rms``/``lam``
        are ignored). Default: the defaults of :class:`SmoothingParams`.

    Returns
    -------
    dict
        ``n_points, dimension, kind, n_faces, n_edges, bbox {min, max}, mean_spacing, phi0,
        tau_range [0, phi0], rms_range [0, r], sigma_estimate, noise, suggested_tau,
        suggested_rms``
        where ``r = sqrt(phi0 / sum omega_i^2)`` over the points that can move and ``n_edges``
        counts neighbour pairs (mesh edges, curve edges, cloud neighbourhood pairs).
        ``noise`` says whether noise was found and on what evidence.
        ``sigma_estimate`` is the noise level across the shape
        (:func:`~service.core.noise.estimate.estimate_noise`), ``suggested_tau`` the tau the
        automatic rule would choose with ``params`` (:func:`~service.core.search.autotau.auto_tau`)
        and
        ``suggested_rms`` the same budget as an RMS displacement; ``None`` when no estimate
        can be made (too few or degenerate points) or when it falls outside ``(0, phi0)``.
    """
    from service.core.search.autotau import auto_tau

    if params is None:
        params = SmoothingParams.model_construct()
    phi0, weight_sum, n_edges, problem = _phi0(geometry, params)
    params, fixed, adjacency = problem.params, problem.fixed, problem.op.neighborhoods.adjacency
    r = tau_to_rms(phi0, weight_sum)
    sigma: float | None = None
    noise: str | None = None
    suggested_tau: float | None = None
    suggested_rms: float | None = None
    if weight_sum > 0:
        try:
            auto = auto_tau(geometry, params, fixed, adjacency)
        except ParameterError:  # no noise estimate
            auto = None
        if auto is not None:
            sigma, noise = auto.sigma, auto.rule.removeprefix("automatic: ")
            tau = auto.tau
            if auto.tau > 0 and not problem.system.empty and _risk(problem):
                tau, sigma, words = _automatic(problem, auto.tau, auto.sigma)
                noise += words
            if 0 < tau < phi0:
                suggested_tau = tau
                suggested_rms = tau_to_rms(tau, weight_sum)
    return {
        "n_points": geometry.n,
        "dimension": geometry.dim,
        "kind": geometry.kind,
        "n_faces": 0 if geometry.faces is None else len(geometry.faces),
        "n_edges": n_edges,
        "bbox": _bbox(geometry.points),
        "mean_spacing": mean_spacing(geometry),
        "phi0": phi0,
        "tau_range": [0.0, phi0],
        "rms_range": [0.0, r],
        "sigma_estimate": sigma,
        "noise": noise,
        "suggested_tau": suggested_tau,
        "suggested_rms": suggested_rms,
    }
