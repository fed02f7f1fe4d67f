"""``describe()``: what an input is and which smoothing factors make sense, without smoothing.

Used by ``geosmooth info``, the API's ``POST /v1/info`` and the web page. It builds the
neighbourhoods and the Laplacian once (as ``smooth`` would) to get ``phi(0)`` of eq. (14), the
upper end of the valid range of ``tau`` (section 6.1), and estimates the noise level (see
:mod:`service.core.search.noise`) to suggest a smoothing factor.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from service.core.errors import ParameterError
from service.core.geometry import Geometry
from service.core.params import SmoothingParams

__all__ = ["describe", "mean_spacing", "valid_range"]


def mean_spacing(geometry: Geometry) -> float:
    """Mean edge length (meshes, curves) or mean nearest-neighbour distance (point clouds)."""
    P = geometry.points
    if geometry.faces is not None:
        F = geometry.faces
        e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    elif geometry.edges is not None:
        e = geometry.edges
    else:
        if geometry.n < 2:
            return 0.0
        d, _ = cKDTree(P).query(P, k=2)
        return float(np.mean(d[:, 1]))
    return float(np.mean(np.linalg.norm(P[e[:, 0]] - P[e[:, 1]], axis=1)))


def _bbox(P: NDArray[np.float64]) -> dict[str, list[float]]:
    return {"min": P.min(axis=0).tolist(), "max": P.max(axis=0).tolist()}


def _phi0(
    geometry: Geometry, params: SmoothingParams, requested: str
) -> tuple[float, float, int, NDArray[np.bool_], Any, SmoothingParams]:
    """``phi(0)`` of the mode ``params`` selects (eq. 14 per component for free displacement,
    fixed points as boundary values; the system's limit for normal displacement), the weight
    sum ``sum omega_i^2`` over the points that can move, the number of neighbour pairs, the
    fixed points and the neighbourhood graph."""
    import scipy.sparse as sp

    from service.core.operator.build import build_operator
    from service.core.pipeline import free_set, smoothing_system
    from service.core.search.target import phi_at_zero_of
    from service.core.system.deviation import Deviation
    from service.core.system.displacement import auto_system

    op = build_operator(geometry, params)
    adj = op.neighborhoods.adjacency
    n_edges = int(sp.triu(adj + adj.T, k=1).nnz)
    fixed, _ = free_set(geometry, op, params, [])
    omega = geometry.omega()
    if fixed.all():
        return 0.0, 0.0, n_edges, fixed, adj, params
    frame = op.frame.weighted(omega[~fixed])
    params, system, _ = auto_system(
        params, requested, lambda p: smoothing_system(geometry, op, fixed, frame, p)
    )
    phi0 = system.phi0
    if phi0 is None:
        solver: Literal["cholmod", "superlu"] = (
            "superlu" if params.solver == "superlu" else "cholmod"
        )
        phi0 = phi_at_zero_of(Deviation(system, solver=solver), op, fixed, params)
    w2 = float(np.sum(omega[~fixed] ** 2))
    return float(phi0) * frame.phi_factor, w2, n_edges, fixed, adj, params


def valid_range(geometry: Geometry, params: SmoothingParams) -> tuple[float, float]:
    """``(phi(0), sum omega_i^2 over the points that can move)`` for ``params``' mode: the
    valid ``tau`` lie in ``(0, phi(0))``, the valid ``rms`` in ``(0, sqrt(phi(0) / sum))``.

    What :func:`describe` reports as ``tau_range`` / ``rms_range``, without its noise estimate
    (the API's check of a given ``tau`` at submit).
    """
    from service.core.system.displacement import resolve_displacement

    requested = params.displacement
    phi0, weight_sum, *_ = _phi0(geometry, resolve_displacement(params, geometry), requested)
    return phi0, weight_sum


def _knee(
    geometry: Geometry, params: SmoothingParams, fixed: NDArray[np.bool_], tau0: float
) -> float:
    """The automatic tau as :func:`~service.core.pipeline.smooth` chooses it: the knee of
    ``phi(lambda)`` near the discrepancy estimate ``tau0`` (Lanczos, no factorization)."""
    from service.core.operator.build import build_operator
    from service.core.pipeline import smoothing_system
    from service.core.search.autotau import knee_tau
    from service.core.system.deviation import Deviation

    op = build_operator(geometry, params)
    frame = op.frame.weighted(geometry.omega()[~fixed])
    system, _ = smoothing_system(geometry, op, fixed, frame, params)
    solver: Literal["cholmod", "superlu"] = "superlu" if params.solver == "superlu" else "cholmod"
    dev = Deviation(system, solver=solver, order=params.order)
    tau = knee_tau(dev, tau0 / frame.phi_factor)
    return tau0 if tau is None else tau * frame.phi_factor


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
        (:func:`~service.core.search.noise.estimate_noise`), ``suggested_tau`` the tau the automatic
        rule would choose with ``params`` (:func:`~service.core.search.autotau.auto_tau`) and
        ``suggested_rms`` the same budget as an RMS displacement; ``None`` when no estimate
        can be made (too few or degenerate points) or when it falls outside ``(0, phi0)``.
    """
    from service.core.search.autotau import auto_tau
    from service.core.system.displacement import resolve_displacement

    if params is None:
        params = SmoothingParams.model_construct()
    requested = params.displacement
    params = resolve_displacement(params, geometry)
    phi0, weight_sum, n_edges, fixed, adjacency, params = _phi0(geometry, params, requested)
    r = float(np.sqrt(phi0 / weight_sum)) if weight_sum > 0 else 0.0
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
            tau = _knee(geometry, params, fixed, auto.tau) if auto.tau > 0 else auto.tau
            if 0 < tau < phi0:
                suggested_tau = tau
                suggested_rms = float(np.sqrt(tau / weight_sum))
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
