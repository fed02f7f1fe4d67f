"""The work of one tile: the whole default run on the tile (core + halo), at a given lambda.

:func:`solve_tile` runs the pipeline's stages (:mod:`service.core.pipeline`: plan, problem with
the data weights, target, finish with the outliers and the tangential step, report) on the
tile's geometry, with the run's one noise estimate (:func:`seeded_noise`) and either

* ``lam=None``: the untiled rule itself (:func:`service.core.pipeline.solve`: knee, search)
  on this tile: the *probe* tile whose lambda the coordinator's rule reads
  (:mod:`.lam`), or
* a lambda (input frame): the same stages with the search replaced by one solve at it.

Only the core's points travel back, with a handful of scalars (:class:`TileSolution`).
"""

from __future__ import annotations

import os
import time
import weakref
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from service.core.geometry import Geometry
from service.core.linalg.cache import analysis_of
from service.core.linalg.resources import choose_solver
from service.core.noise import estimate as noise_estimate
from service.core.noise.estimate import NoiseEstimate
from service.core.params import SmoothingParams
from service.core.pipeline import finish, plan_and_prepare, report, solve, target, unchanged
from service.core.plan import Plan
from service.core.problem import Problem
from service.core.result import SmoothResult
from service.core.run import Run
from service.core.search.roots import LambdaSearch
from service.core.search.target import Solution
from service.core.system.deviation import Deviation
from service.core.tiles.halo import operator_norm_bound
from service.core.tiles.partition import hop_radius
from service.core.warnings import EngineWarning

__all__ = ["TileSolution", "core_phi", "seeded_noise", "solve_tile"]


@dataclass(frozen=True)
class TileSolution:
    """One tile smoothed by the default (scalars besides the core's points).

    Attributes
    ----------
    points : ndarray, shape (n_core, s)
        The core's smoothed points (input order of the core).
    phi : float
        ``sum_core omega_i^2 ||x_i - p_i||^2`` with the tile's data weights.
    lam : float
        The lambda solved at (input frame).
    tau : float or None
        The tile's target (its knee's, for the probe; else its ``tau_0``), whole tile.
    outliers : ndarray of int
        Core points the data weights treated as outliers (core-local indices).
    norm, reach, lam_scale, omega_low : float
        For the halo (:mod:`.halo`): a bound of ``||L||_2`` (no iteration: Lanczos cost 6 s
        on a 107K-point probe tile, a third of the tile), Euclidean reach per hop, ``s^(2p) w^2``
        (internal per input lambda) and the 1st percentile of the free points' weights over
        their frame scale.
    unchanged : bool
        The default returned the tile as it was (no noise found, nothing can move).
    """

    points: NDArray[np.float64]
    phi: float
    lam: float
    tau: float | None
    outliers: NDArray[np.int64]
    factorizations: int
    solves: int
    solver: str
    seconds: float
    warnings: list[EngineWarning]
    norm: float = 0.0
    reach: float = 0.0
    lam_scale: float = 1.0
    omega_low: float = 1.0
    unchanged: bool = False
    n_halo: int = 0
    worker: str = field(default_factory=lambda: f"pid {os.getpid()}")


def seeded_noise(geometry: Geometry, est: NoiseEstimate | None) -> None:
    """Make ``est`` (the whole input's estimate) the noise estimate of ``geometry``'s runs.

    Every stage asks :func:`service.core.noise.estimate.estimate_noise` for the estimate of
    the points array it holds; this seeds its memo with the global one (its per-point
    neighbours dropped), so the data weights, tau_0 and the checks of a tile read one noise
    level. ``None`` leaves the tile to estimate its own (no global estimate was possible)."""
    if est is None:
        return
    key = (None, float(np.sum(geometry.points)))
    kept = NoiseEstimate(est.sigma, est.manifold_dim, est.k, est.points_used, est.residuals,
                         est.roughness, est.scale_ratio, None, est.track)  # fmt: skip
    noise_estimate._MEMO[:] = [(weakref.ref(geometry.points), key, kept)]


def core_phi(omega: NDArray[np.float64], X: NDArray[np.float64], P: NDArray[np.float64]) -> float:
    """``sum omega_i^2 ||x_i - p_i||^2`` over the rows given."""
    return float(np.sum(omega**2 * np.sum((X - P) ** 2, axis=1)))


def _sources(P: NDArray[np.float64], count: int = 4) -> NDArray[np.int64]:
    """Points to measure the hop reach from: the one nearest the centre, ``count - 1`` seeded."""
    centre = int(np.argmin(np.sum((P - P.mean(axis=0)) ** 2, axis=1)))
    more = np.random.default_rng(0).choice(P.shape[0], size=min(count - 1, P.shape[0]),
                                           replace=False)  # fmt: skip
    return np.unique(np.concatenate([[centre], more])).astype(np.int64)


def _at_lambda(problem: Problem, plan: Plan, run: Run, lam: float,
               memory_limit: int | None) -> Solution:  # fmt: skip
    """The solve stage with the search replaced by one solve at ``lam`` (input frame)."""
    aim = target(problem, plan)
    if problem.system.empty or (plan.automatic_tau and not aim.tau):
        return unchanged(problem, plan, aim, run)
    params, system = problem.params, problem.system
    t0 = time.perf_counter()
    solver = choose_solver(system, params, memory_limit, run.warn)
    dev = Deviation(system, solver=solver, order=params.order, reuse=True, symbolic=analysis_of)
    inner = problem.frame.lam_in(lam)
    if params.solver == "auto":  # CG: 0.5 s against CHOLMOD's 1.6 s on a 63K tile at the
        dev.use_matrix_free()  # default's lambda (the untiled default is matrix-free too)
    phi = dev(inner)
    search = LambdaSearch(inner, phi, True, list(dev.history))
    return Solution(aim, search, dev.solution(inner), dev, None, time.perf_counter() - t0)


def solve_tile(
    geometry: Geometry,
    n_core: int,
    params: SmoothingParams,
    lam: float | None,
    noise: NoiseEstimate | None,
    memory_limit: int | None = None,
    measure: bool = False,
) -> TileSolution:
    """The default on the tile (core first in ``geometry``): its own rule when ``lam`` is
    ``None`` (the probe), else one solve at ``lam`` (input frame); the core's result, with the
    halo's numbers when ``measure``."""
    t0 = time.perf_counter()
    seeded_noise(geometry, noise)
    run = Run(None)
    plan, problem = plan_and_prepare(geometry, params, None)
    if lam is None:
        aim = target(problem, plan)
        sol = solve(problem, plan, aim, run, memory_limit)
    else:
        sol = _at_lambda(problem, plan, run, lam, memory_limit)
    res = report(problem, plan, run, sol, finish(problem, plan, sol))
    tile = _core_of(geometry, problem, res, n_core, sol, time.perf_counter() - t0)
    return _measured(tile, geometry, problem, n_core) if measure else tile


def _measured(tile: TileSolution, geometry: Geometry, problem: Problem,
              n_core: int) -> TileSolution:  # fmt: skip
    """The probe's numbers for the halo (:mod:`.halo`): norm, reach per hop, frame scales."""
    omega = problem.geometry.omega()[~problem.fixed] / problem.frame.weight_scale
    op = problem.op
    return replace(
        tile,
        norm=operator_norm_bound(op.L),
        reach=hop_radius(geometry.points, op.neighborhoods.adjacency,
                         _sources(geometry.points[:n_core])),
        lam_scale=problem.frame.lam_in(1.0),
        omega_low=float(np.quantile(omega, 0.01)) if omega.size else 1.0,
    )


def _core_of(geometry: Geometry, problem: Problem, res: SmoothResult, n_core: int,
             sol: Solution, seconds: float) -> TileSolution:  # fmt: skip
    """The core's share of a tile's result."""
    omega = problem.geometry.omega()
    outliers = np.asarray(res.outliers if res.outliers is not None else [], dtype=np.int64)
    return TileSolution(
        points=res.points[:n_core].copy(),
        phi=core_phi(omega[:n_core], res.points[:n_core], geometry.points[:n_core]),
        lam=float(res.lam),
        tau=res.tau,
        outliers=outliers[outliers < n_core],
        factorizations=res.factorizations,
        solves=res.solves,
        solver=res.solver,
        seconds=seconds,
        warnings=list(res.warnings),
        unchanged=sol.U is None,
        n_halo=geometry.n - n_core,
    )
