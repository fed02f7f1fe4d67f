"""``smooth_tiled``: one smoothing over spatial tiles with halos and one global budget.

Round 0 cuts the input into cores of about ``tile_points`` points (:func:`.partition.kd_split`)
with a provisional halo of :data:`PROBE_HOPS` hops and probes every tile
(:func:`.solve.probe_tile`): its share of the budget, its operator norm and its weights. The
coordinator then knows tau (given; ``rms^2 sum omega^2``; or automatic, from the tiles' noise
estimates pooled), a model of every share of phi, and the halo the lambda found needs
(:mod:`.halo`); tiles are re-cut if their halo is too narrow, and the rounds of
:func:`.budget.solve_budget` solve every tile at the candidate lambda. The stitched result holds
each core's points from its own tile.

The tiles' work goes through ``run_map(function, argument_tuples)`` (default: in this process,
one after the other), so a process pool or a job queue can run them.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np

from service.core.checks.guards import shape_checks
from service.core.errors import ParameterError
from service.core.geometry import Geometry
from service.core.params import SmoothingParams
from service.core.progress import ProgressCallback, ProgressEvent
from service.core.result import SmoothResult
from service.core.system.displacement import FRAME_STEPS, resolve_displacement
from service.core.tiles.budget import PhiModel, solve_budget
from service.core.tiles.halo import HALO_EPS, MAX_HOPS, decay_rate, halo_hops
from service.core.tiles.partition import Tile, hop_length, kd_split, tile_geometry, tile_members
from service.core.tiles.solve import TileProbe, TileSolution, probe_tile, solve_tile
from service.core.warnings import warning

__all__ = ["PROBE_HOPS", "TileReport", "TiledResult", "check_tileable", "smooth_tiled"]

T = TypeVar("T")
RunMap = Callable[[Callable[..., T], list[tuple[Any, ...]]], list[T]]
#: Halo of round 0 (hops); kept when the lambda found needs no more.
PROBE_HOPS = 12


@dataclass(frozen=True)
class TileReport:
    """One tile in the report: points, halo, worker, seconds, its share of phi."""

    index: int
    points: int
    halo: int
    hops: int
    worker: str
    seconds: float
    phi: float
    factorizations: int


@dataclass(frozen=True)
class TiledResult:
    """The stitched :class:`SmoothResult` plus the tiles, rounds and halo."""

    result: SmoothResult
    tiles: list[TileReport]
    rounds: int
    hops: int
    hop_length: float


def _serial(fn: Callable[..., T], args: list[tuple[Any, ...]]) -> list[T]:
    return [fn(*a) for a in args]


def check_tileable(params: SmoothingParams) -> None:
    """Refuse what has no tiled form (global post-processing or global scales).

    Raises
    ------
    ParameterError
    """
    bad = {
        "params.preserve_volume": params.preserve_volume,
        "params.max_deviation": params.max_deviation is not None,
        "params.spectrum": params.spectrum,
        "params.tau": params.tau_rule == "gcv",
        "params.method": params.method == "windowed-sinc",
        "params.laplacian": params.laplacian == "feature",
        "params.robust": params.robust not in ("auto", "none"),
        "params.noise_weights": params.noise_weights not in ("auto", "none"),
    }
    for name, on in bad.items():
        if on:
            raise ParameterError(
                f"{name.split('.')[1]}={getattr(params, name.split('.')[1])!r} has no tiled form "
                "(a global rescaling, bound, spectrum, pass band, curvature scale or data "
                "weights from the noise): "
                "drop tile_points or this option",
                field=name,
            )


def required_hops(probes: Sequence[TileProbe], lam: float, params: SmoothingParams) -> int:
    """The halo (hops) every tile needs at ``lam`` (:mod:`.halo`): the smallest decay rate."""
    alpha = min(decay_rate(lam * p.lam_scale, p.norm, p.omega_min) for p in probes)
    extra = 2 + (FRAME_STEPS + 2 if params.displacement == "normal" else 0)
    return halo_hops(alpha, params.order, HALO_EPS, extra)


def _tiles(geometry: Geometry, cores: list[np.ndarray], hops: int, hop: float) -> list[Tile]:
    return [Tile(c, tile_members(geometry.points, c, hops * hop), hops) for c in cores]


def _emit(progress: ProgressCallback | None, t0: float, stage: str, **kw: Any) -> None:
    if progress is not None:
        progress(ProgressEvent(stage, elapsed=time.perf_counter() - t0, **kw))


def _global_tau(
    geometry: Geometry, params: SmoothingParams, probes: Sequence[TileProbe]
) -> float | None:
    """tau over the whole input: given, ``rms^2 sum omega^2`` (free points), or automatic:
    every tile's automatic share rescaled to the pooled noise
    ``sigma^2 = sum_t n_t sigma_t^2 / sum_t n_t``."""
    rule = params.tau_rule
    if rule == "lam":
        return None
    if rule == "tau":
        return float(params.tau)  # type: ignore[arg-type]
    w2 = geometry.omega()[~geometry.fixed_mask()] ** 2
    if rule == "rms":
        assert params.rms is not None
        return float(params.rms**2 * w2.sum())
    est = [(p.n_core, p.sigma, p.tau) for p in probes if p.sigma and p.tau]
    if not est:
        raise ParameterError("the noise level of this input cannot be estimated: give tau, "
                             "rms or lam", field="params.tau")
    n = sum(e[0] for e in est)
    pooled = sum(e[0] * e[1] ** 2 for e in est) / n  # type: ignore[operator]
    share = sum(e[2] * pooled / e[1] ** 2 for e in est)  # type: ignore[operator]
    return float(share * (sum(p.n_core for p in probes) / n))


def smooth_tiled(
    geometry: Geometry,
    params: SmoothingParams,
    tile_points: int,
    progress: ProgressCallback | None = None,
    run_map: RunMap[Any] | None = None,
    memory_limit: int | None = None,
) -> TiledResult:
    """Smooth ``geometry`` tile by tile with one global tau (module docstring).

    Raises
    ------
    ParameterError
        Options without a tiled form (:func:`check_tileable`), ``tile_points < 1``.
    """
    if tile_points < 1:
        raise ParameterError("tile_points must be at least 1", field="params.tile_points")
    check_tileable(params)
    t0 = time.perf_counter()
    mapper: RunMap[Any] = run_map or _serial
    # data weights from the noise (issue 21) are one global choice; tiles keep the user's
    params = resolve_displacement(params, geometry).model_copy(
        update={"tile_points": None, "robust": "none", "noise_weights": "none"})
    cores = kd_split(geometry.points, tile_points)
    hop = hop_length(geometry, params.k)
    tiles = _tiles(geometry, cores, PROBE_HOPS, hop)
    _emit(progress, t0, "neighborhoods")
    w2 = geometry.omega() ** 2
    free = ~geometry.fixed_mask()
    total_w2 = max(float(w2[free].sum()), 1e-300)
    tau0 = _global_tau(geometry, params, []) if params.tau_rule in ("tau", "rms") else None
    args = [
        (tile_geometry(geometry, t.members), t.n_core, params,
         None if tau0 is None else tau0 * float(w2[t.members][free[t.members]].sum()) / total_w2,
         memory_limit)
        for t in tiles
    ]
    probes: list[TileProbe] = mapper(probe_tile, args)
    hop = max((p.reach for p in probes), default=0.0) or hop
    tau = _global_tau(geometry, params, probes)
    _emit(progress, t0, "analysis", tau=tau)
    solutions: dict[int, TileSolution] = {}

    def evaluate(lam: float) -> list[float]:
        nonlocal tiles
        need = required_hops(probes, lam, params)
        if need > tiles[0].hops:
            tiles = _tiles(geometry, cores, need, hop)
        jobs = [(tile_geometry(geometry, t.members), t.n_core, params, lam, memory_limit)
                for t in tiles]
        sols: list[TileSolution] = mapper(solve_tile, jobs)
        solutions.clear()
        solutions.update(enumerate(sols))
        phis = [s.phi for s in sols]
        _emit(progress, t0, "search", tau=tau, iteration=len(history) + 1, lam=lam,
              phi=sum(phis))
        history.append(lam)
        return phis

    history: list[float] = []
    if tau is None:
        assert params.lam is not None
        evaluate(params.lam)
        lam, phi, rounds, converged, lam_history = params.lam, None, 1, True, []
    else:
        models = [PhiModel.of(p.history, p.core_ratio) for p in probes]
        budget = solve_budget(tau, models, evaluate, params.tolerance)
        if budget.lam != history[-1]:
            evaluate(budget.lam)
        lam, phi, rounds, converged = budget.lam, budget.phi, budget.rounds, budget.converged
        lam_history = budget.history
    _emit(progress, t0, "postprocess", tau=tau, iteration=len(history))
    return _stitch(geometry, params, tiles, probes, solutions, tau, lam, phi, rounds,
                   converged, lam_history, hop, time.perf_counter() - t0)


def _stitch(
    geometry: Geometry,
    params: SmoothingParams,
    tiles: list[Tile],
    probes: list[TileProbe],
    solutions: dict[int, TileSolution],
    tau: float | None,
    lam: float,
    phi: float | None,
    rounds: int,
    converged: bool,
    history: list[tuple[float, float]],
    hop: float,
    seconds: float,
) -> TiledResult:
    """Every core's points from its tile, and the whole run's :class:`SmoothResult`."""
    X = geometry.points.copy()
    for i, t in enumerate(tiles):
        X[t.core] = solutions[i].points
    total = float(sum(s.phi for s in solutions.values())) if phi is None else phi
    dev = np.linalg.norm(X - geometry.points, axis=1)
    warnings = sorted({w for s in solutions.values() for w in s.warnings}, key=str)
    if tiles[0].hops >= MAX_HOPS:
        warnings.append(warning("halo-capped", f"the halo was capped at {MAX_HOPS} hops: seams "
                                "may show", hops=MAX_HOPS))  # fmt: skip
    result = SmoothResult(
        points=X, lam=float(lam), phi=total, tau=tau,
        relative_error=None if tau is None else abs(total - tau) / tau,
        converged=converged, iterations=rounds,
        factorizations=sum(s.factorizations for s in solutions.values()),
        history=list(history), deviation=dev,
        rms_displacement=float(np.sqrt(np.mean(dev**2))), max_displacement=float(dev.max()),
        timings={"total": seconds}, solver=next(iter(solutions.values())).solver,
        laplacian=params.laplacian, weights=params.weights, kind=geometry.kind,
        solves=sum(s.solves for s in solutions.values()), search="tiles",
        order=params.order, n_fixed=int(geometry.fixed_mask().sum()), warnings=warnings,
        displacement=params.displacement, tau_rule=params.tau_rule,
        sigma_estimate=_pooled_sigma(probes),
        checks=shape_checks(geometry, X).to_dict(),
    )
    reports = [
        TileReport(i, t.n_core, t.n_halo, t.hops, solutions[i].worker,
                   solutions[i].seconds + probes[i].seconds, solutions[i].phi,
                   solutions[i].factorizations)
        for i, t in enumerate(tiles)
    ]
    return TiledResult(result, reports, rounds, tiles[0].hops, hop)


def _pooled_sigma(probes: Sequence[TileProbe]) -> float | None:
    """The noise the tiled tau was pooled from: over the tiles whose estimate found noise, as
    in :func:`_global_tau` (a tile whose residuals read as shape, ``sigma = 0``, takes no part
    in the budget and must not pull the reported level down: on a terrain cloud with noise
    0.1 whose scale ratio is near the limit, two of four tiles read as shape and the average
    over all four was 0.06 against the untiled 0.12)."""
    est = [(p.n_core, p.sigma) for p in probes if p.sigma and p.tau]
    if not est:
        return next((0.0 for p in probes if p.sigma is not None), None)
    return math.sqrt(sum(n * s**2 for n, s in est) / sum(n for n, _ in est))
