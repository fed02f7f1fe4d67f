"""The work of one tile: a probe (round 0) and a solve at a given lambda (later rounds).

Both run :func:`service.core.pipeline.smooth_one` on the tile's geometry (core + halo) with the
operator built on the tile, so fixed points, weights, the Laplacian variant, the displacement
mode and the solver paths are those of an untiled run; only the core's points are returned.
What travels back to the coordinator besides the core's points is a handful of scalars
(:class:`TileProbe`, :class:`TileSolution`).
"""

from __future__ import annotations

import os
import time
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from service.core.geometry import Geometry
from service.core.operator.build import SmoothingOperator, build_operator, operator_key
from service.core.params import SmoothingParams
from service.core.pipeline import smooth_one as smooth
from service.core.tiles.halo import spectral_norm
from service.core.tiles.partition import hop_radius
from service.core.warnings import EngineWarning

__all__ = ["CACHE_POINTS", "TileProbe", "TileSolution", "probe_tile", "solve_tile"]

#: Points whose tile operators a process keeps between rounds (least recently used dropped).
CACHE_POINTS = 4_000_000
_operators: OrderedDict[str, tuple[int, SmoothingOperator]] = OrderedDict()


@dataclass(frozen=True)
class TileProbe:
    """Round 0 of one tile: its own search and what the coordinator needs (scalars only).

    Attributes
    ----------
    lam : float or None
        The tile's lambda for its share of tau (input frame); ``None`` for a given lambda.
    history : list of (float, float)
        ``(lambda, phi)`` of the tile's search (the whole tile).
    core_ratio : float
        ``phi_core / phi_tile`` at ``lam`` (the model of the core's phi).
    tau, sigma : float or None
        The tile's automatic tau (core share) and noise estimate.
    norm : float
        ``||L||_2`` of the tile's operator (internal frame, :func:`.halo.spectral_norm`).
    reach : float
        Euclidean reach per graph hop (:func:`.partition.hop_radius`, input frame).
    lam_scale : float
        ``s^(2p)``: the internal lambda per input lambda, before weights.
    omega_min : float
        Smallest weight of the tile's free points.
    n_core, n_halo : int
    seconds : float
    worker : str
    """

    lam: float | None
    history: list[tuple[float, float]]
    core_ratio: float
    tau: float | None
    sigma: float | None
    norm: float
    reach: float
    lam_scale: float
    omega_min: float
    n_core: int
    n_halo: int
    seconds: float
    worker: str = field(default_factory=lambda: f"pid {os.getpid()}")


@dataclass(frozen=True)
class TileSolution:
    """One tile solved at a given lambda.

    Attributes
    ----------
    points : ndarray, shape (n_core, s)
        The core's smoothed points (input order of the core).
    phi : float
        ``sum_core omega_i^2 ||x_i - p_i||^2``: the tile's share of eq. (15).
    factorizations, solves : int
    solver : str
    seconds : float
    warnings : list of EngineWarning
    worker : str
    """

    points: NDArray[np.float64]
    phi: float
    factorizations: int
    solves: int
    solver: str
    seconds: float
    warnings: list[EngineWarning]
    worker: str = field(default_factory=lambda: f"pid {os.getpid()}")


def _operator(geometry: Geometry, params: SmoothingParams) -> SmoothingOperator:
    """The tile's operator, kept between rounds (up to :data:`CACHE_POINTS` points)."""
    key = operator_key(geometry, params)
    if key in _operators:
        _operators.move_to_end(key)
        return _operators[key][1]
    op = build_operator(geometry, params)
    _operators[key] = (geometry.n, op)
    while sum(n for n, _ in _operators.values()) > CACHE_POINTS and len(_operators) > 1:
        _operators.popitem(last=False)
    return op


def core_phi(geometry: Geometry, X: NDArray[np.float64], n_core: int) -> float:
    """``sum_core omega_i^2 ||x_i - p_i||^2`` (fixed points do not move)."""
    moved = X[:n_core] - geometry.points[:n_core]
    return float(np.sum(geometry.omega()[:n_core] ** 2 * np.sum(moved**2, axis=1)))


def _sources(geometry: Geometry, n_core: int, count: int = 4) -> NDArray[np.int64]:
    """Core points to measure the hop reach from: the one nearest the core's centre and
    ``count - 1`` drawn at random (seeded)."""
    P = geometry.points[:n_core]
    centre = int(np.argmin(np.sum((P - P.mean(axis=0)) ** 2, axis=1)))
    rng = np.random.default_rng(0)
    more = rng.choice(n_core, size=min(count - 1, n_core), replace=False)
    return np.unique(np.concatenate([[centre], more])).astype(np.int64)


def probe_tile(
    geometry: Geometry,
    n_core: int,
    params: SmoothingParams,
    tau_share: float | None,
    memory_limit: int | None = None,
) -> TileProbe:
    """Round 0: the tile's operator norm and, unless lambda is given, its own search for
    ``tau_share`` (a number, or ``params.tau`` when ``None``: the automatic rule)."""
    t0 = time.perf_counter()
    op = _operator(geometry, params)
    fixed = geometry.fixed_mask()
    omega = geometry.omega()[~fixed]
    norm = spectral_norm(op.L)
    reach = hop_radius(geometry.points, op.neighborhoods.adjacency, _sources(geometry, n_core))
    lam_scale = op.frame.scale ** (2 * op.frame.power)
    omega_min = float(omega.min()) if omega.size else 1.0
    lam = tau = sigma = None
    history: list[tuple[float, float]] = []
    ratio = 1.0
    if params.lam is None:
        update = {"tau": tau_share, "rms": None} if tau_share is not None else {}
        res = smooth(geometry, params.model_copy(update=update), operator=op,
                     memory_limit=memory_limit)
        lam, history, sigma = res.lam, res.history, res.sigma_estimate
        phi_core = core_phi(geometry, res.points, n_core)
        ratio = phi_core / res.phi if res.phi > 0 else 1.0
        w2 = geometry.omega() ** 2
        share = float(w2[:n_core][~fixed[:n_core]].sum() / max(w2[~fixed].sum(), 1e-300))
        tau = None if res.tau is None else res.tau * share
    return TileProbe(lam, history, ratio, tau, sigma, norm, reach, lam_scale, omega_min,
                     n_core, geometry.n - n_core, time.perf_counter() - t0)


def solve_tile(
    geometry: Geometry,
    n_core: int,
    params: SmoothingParams,
    lam: float,
    memory_limit: int | None = None,
) -> TileSolution:
    """The tile smoothed at ``lam`` (input frame); the core's points and phi."""
    t0 = time.perf_counter()
    op = _operator(geometry, params)
    given = params.model_copy(update={"lam": lam, "tau": None, "rms": None})
    res = smooth(geometry, given, operator=op, memory_limit=memory_limit)
    return TileSolution(
        res.points[:n_core].copy(),
        core_phi(geometry, res.points, n_core),
        res.factorizations,
        res.solves,
        res.solver,
        time.perf_counter() - t0,
        list(res.warnings),
    )
