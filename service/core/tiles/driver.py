"""``smooth_tiled``: the default run over spatial tiles with halos, one noise level, one lambda.

1. Cores of about ``tile_points`` points (:func:`.partition.kd_split`, or the caller's: the
   files of a dataset), one noise estimate of the whole input (the untiled run's, a sample).
2. The lambda rule (:mod:`.lam`, pluggable) looks at the probe tile, the core nearest the
   input's centre with a provisional halo of :data:`PROBE_HOPS` hops: today the untiled rule
   run there, whose solution is kept.
3. The halo that lambda needs (:mod:`.halo`, from the probe's ``||L||``, reach per hop and
   weights); every other tile (and the probe, if its halo was too narrow) runs the whole
   default at that lambda (:func:`.solve.solve_tile`: data weights on core + halo, outliers,
   the tangential step, the checks), in chunks through ``run_map``, each chunk's tiles cut
   from the input only when it starts.
4. Each core's points from its own tile; the shape checks on the stitched result.

Progress: one ``search`` event per chunk with the tiles done and total, points per second and
the time left (measured tiles' seconds per point times the points left).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np

from service.core.checks.guards import shape_checks
from service.core.errors import ParameterError
from service.core.geometry import Geometry
from service.core.noise.estimate import NoiseEstimate, estimate_noise
from service.core.params import SmoothingParams
from service.core.progress import ProgressCallback, ProgressEvent
from service.core.result import SmoothResult
from service.core.system.displacement import FRAME_STEPS, resolve_displacement
from service.core.tiles.halo import HALO_EPS, MAX_HOPS, RATE_MARGIN, decay_rate, halo_hops
from service.core.tiles.lam import LambdaDecision, LambdaRule, ProbeTile, probe_rule
from service.core.tiles.partition import Tile, hop_length, kd_split, tile_geometry, tile_members
from service.core.tiles.solve import TileSolution, solve_tile
from service.core.warnings import EngineWarning, warning

__all__ = ["PROBE_HOPS", "TileReport", "TiledResult", "check_tileable", "smooth_tiled"]

T = TypeVar("T")
RunMap = Callable[[Callable[..., T], list[tuple[Any, ...]]], list[T]]
#: Halo of the probe tile (hops), kept when the lambda found needs no more.
PROBE_HOPS = 16


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
    """The stitched :class:`SmoothResult` plus the tiles, the lambda decision and the halo."""

    result: SmoothResult
    tiles: list[TileReport]
    rounds: int
    hops: int
    hop_length: float
    probe: int = 0
    lam_how: str = ""


def _serial(fn: Callable[..., T], args: list[tuple[Any, ...]]) -> list[T]:
    return [fn(*a) for a in args]


def check_tileable(params: SmoothingParams) -> None:
    """Refuse what has no tiled form (global post-processing, global scales or spectra).

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
    }
    for name, on in bad.items():
        if on:
            raise ParameterError(
                f"{name.split('.')[1]}={getattr(params, name.split('.')[1])!r} has no tiled form "
                "(a global rescaling, bound, spectrum, pass band or curvature scale): "
                "drop tile_points or this option",
                field=name,
            )


def required_hops(probe: TileSolution, lam: float, params: SmoothingParams) -> int:
    """The halo (hops) at ``lam`` (input frame) from the probe's norm and weights."""
    alpha = RATE_MARGIN * decay_rate(lam * probe.lam_scale, probe.norm, probe.omega_low)
    extra = 2 + (FRAME_STEPS + 2 if params.displacement == "normal" else 0)
    return halo_hops(alpha, params.order, HALO_EPS, extra)


def central(geometry: Geometry, cores: list[np.ndarray]) -> int:
    """The core whose centroid is nearest the median point (the probe tile)."""
    mid = np.median(geometry.points, axis=0)
    return int(np.argmin([np.sum((geometry.points[c].mean(axis=0) - mid) ** 2) for c in cores]))


def _emit(progress: ProgressCallback | None, t0: float, stage: str, **kw: Any) -> None:
    if progress is not None:
        progress(ProgressEvent(stage, elapsed=time.perf_counter() - t0, **kw))


class _Clock:
    """Tiles done, points per second and the time left. The rate is measured from the probe's
    start until a tile at the fixed lambda is done, then on those tiles alone (the probe
    searches: slower per point than the others, so its rate alone overstates the time left)."""

    def __init__(self, geometry: Geometry, tiles: int, progress: ProgressCallback | None,
                 t0: float) -> None:  # fmt: skip
        self.total, self.tiles, self.progress, self.t0 = geometry.n, tiles, progress, t0
        self.points = self.done = 0
        self.lam: float | None = None
        self.start = time.perf_counter()
        self.since: tuple[float, int] | None = None  # (clock, points) after the probe

    def tick(self, points: int, tiles: int) -> None:
        """``tiles`` more tiles with ``points`` points done (the first call: the probe's)."""
        now = time.perf_counter()
        self.points += points
        self.done += tiles
        since = self.since = self.since or (now, self.points)
        start, base = (self.start, 0) if self.points == since[1] else since
        rate = (self.points - base) / (now - start) if now > start and self.points > base \
            else None
        left = None if rate is None else (self.total - self.points) / rate
        _emit(self.progress, self.t0, "search", lam=self.lam, iteration=1,
              fraction=self.points / max(self.total, 1), tiles_done=self.done,
              tiles_total=self.tiles, points_per_second=rate, seconds_left=left)


def smooth_tiled(
    geometry: Geometry,
    params: SmoothingParams,
    tile_points: int,
    progress: ProgressCallback | None = None,
    run_map: RunMap[Any] | None = None,
    memory_limit: int | None = None,
    *,
    cores: list[np.ndarray] | None = None,
    rule: LambdaRule = probe_rule,
) -> TiledResult:
    """The default over tiles with one noise estimate and one lambda (module docstring).

    Parameters
    ----------
    cores : list of ndarray of int, optional
        The cores (disjoint, covering every point), e.g. one per file of a dataset; default:
        :func:`.partition.kd_split` at ``tile_points``.
    rule : callable
        The lambda rule (:mod:`.lam`).

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
    params = resolve_displacement(params, geometry).model_copy(update={"tile_points": None})
    cores = kd_split(geometry.points, tile_points) if cores is None else cores
    _emit(progress, t0, "neighborhoods", step="noise")
    noise = estimate_noise(geometry)  # the one estimate (a sample of the whole input)
    hop = hop_length(geometry, params.k)
    first = central(geometry, cores)
    probe_tile = Tile(cores[first], tile_members(geometry.points, cores[first],
                                                 PROBE_HOPS * hop), PROBE_HOPS)  # fmt: skip
    _emit(progress, t0, "analysis")
    clock = _Clock(geometry, len(cores), progress, t0)

    def run_tile(g: Geometry, n_core: int, p: SmoothingParams, lam: float | None) -> TileSolution:
        return mapper(solve_tile, [(g, n_core, p, lam, noise, memory_limit, True)])[0]

    share = _share(geometry, probe_tile.members)
    decision = rule(ProbeTile(tile_geometry(geometry, probe_tile.members), probe_tile.n_core,
                              share), params, run_tile)  # fmt: skip
    if decision.lam is None:
        return _unchanged(geometry, params, cores, decision, noise, hop,
                          time.perf_counter() - t0)
    lam = decision.lam
    solved: dict[int, TileSolution] = {}
    hops = PROBE_HOPS
    if decision.probe is not None:
        hop = decision.probe.reach or hop
        hops = max(required_hops(decision.probe, lam, params), 1)
        if hops <= PROBE_HOPS:
            solved[first] = decision.probe
    tiles = [Tile(c, np.zeros(0, np.int64), hops) for c in cores]
    if first in solved:
        tiles[first] = probe_tile
    clock.lam = lam
    _run_tiles(geometry, params, tiles, solved, lam, noise, hop, mapper, memory_limit, clock)
    return _stitch(geometry, params, tiles, solved, decision, noise, hop, first,
                   time.perf_counter() - t0, share)


def _share(geometry: Geometry, members: np.ndarray) -> float:
    """The tile's (core + halo) share of ``sum omega^2`` over the free points: the share of a
    given tau its own search meets (its phi counts the halo too)."""
    w2 = geometry.omega() ** 2
    free = ~geometry.fixed_mask()
    return float(w2[members][free[members]].sum() / max(w2[free].sum(), 1e-300))


def _run_tiles(
    geometry: Geometry, params: SmoothingParams, tiles: list[Tile],
    solved: dict[int, TileSolution], lam: float, noise: NoiseEstimate | None, hop: float,
    mapper: RunMap[Any], memory_limit: int | None, clock: _Clock,
) -> None:  # fmt: skip
    """Every tile not yet in ``solved`` at ``lam``, ``workers`` tiles at a time (the run map's
    ``workers`` attribute, default 1), cut from the input when its chunk starts."""
    clock.tick(sum(tiles[i].n_core for i in solved), len(solved))  # the probe, when kept
    todo = [i for i in range(len(tiles)) if i not in solved]
    step = max(int(getattr(mapper, "workers", 1) or 1), 1)
    for at in range(0, len(todo), step):
        chunk = todo[at:at + step]
        members = {i: tile_members(geometry.points, tiles[i].core, tiles[i].hops * hop)
                   for i in chunk}  # fmt: skip
        jobs = [(tile_geometry(geometry, members[i]), tiles[i].n_core, params, lam, noise,
                 memory_limit) for i in chunk]  # fmt: skip
        for i, sol in zip(chunk, mapper(solve_tile, jobs), strict=True):
            solved[i] = sol
            tiles[i] = Tile(tiles[i].core, members[i], tiles[i].hops)
        del jobs
        clock.tick(sum(tiles[i].n_core for i in chunk), len(chunk))


def _stitch(
    geometry: Geometry, params: SmoothingParams, tiles: list[Tile],
    solved: dict[int, TileSolution], decision: LambdaDecision, noise: NoiseEstimate | None,
    hop: float, probe: int, seconds: float, share: float,
) -> TiledResult:  # fmt: skip
    """Every core's points from its tile, and the whole run's :class:`SmoothResult`: tau is
    the given one, or the probe's target over its weight ``share`` (so ``relative_error``
    says how far the whole input's phi is from the rule's budget)."""
    X = geometry.points.copy()
    for i, t in enumerate(tiles):
        X[t.core] = solved[i].points
    sols = [solved[i] for i in range(len(tiles))]
    phi = float(sum(s.phi for s in sols))
    tau = _given_tau(geometry, params)
    if tau is None and decision.probe is not None and decision.probe.tau and share:
        tau = decision.probe.tau / share  # the rule's target carried to the whole input
    dev = np.linalg.norm(X - geometry.points, axis=1)
    outliers = np.sort(np.concatenate([t.core[s.outliers] for t, s in zip(tiles, sols,
                                                                           strict=True)]))
    warnings = _merged([w for s in sols for w in s.warnings], int(outliers.size))
    if tiles[0].hops >= MAX_HOPS:
        warnings.append(warning("halo-capped", f"the halo was capped at {MAX_HOPS} hops: seams "
                                "may show", hops=MAX_HOPS))  # fmt: skip
    result = SmoothResult(
        points=X, lam=float(decision.lam or 0.0), phi=phi, tau=tau,
        relative_error=None if tau is None else abs(phi - tau) / tau,
        converged=True, iterations=1, factorizations=sum(s.factorizations for s in sols),
        history=[], deviation=dev, rms_displacement=float(np.sqrt(np.mean(dev**2))),
        max_displacement=float(dev.max(initial=0.0)), timings={"total": seconds},
        solver=sols[probe].solver, laplacian=params.laplacian, weights=params.weights,
        kind=geometry.kind, solves=sum(s.solves for s in sols), search="tiles",
        order=params.order, n_fixed=int(geometry.fixed_mask().sum()), warnings=warnings,
        displacement=params.displacement, tau_rule=params.tau_rule,
        sigma_estimate=None if noise is None else noise.sigma,
        noise_found=None if noise is None else noise.noise_found,
        tau_how=f"lambda {decision.lam:.6g}: {decision.how}" if decision.lam else decision.how,
        checks=shape_checks(geometry, X).to_dict(), outliers=outliers.astype(np.int64),
        outlier_mode=params.outliers if outliers.size else None,
        data_weights=params.robust if outliers.size else None,
    )
    reports = [TileReport(i, t.n_core, t.n_halo, t.hops, solved[i].worker, solved[i].seconds,
                          solved[i].phi, solved[i].factorizations)
               for i, t in enumerate(tiles)]  # fmt: skip
    return TiledResult(result, reports, 1, max(t.hops for t in tiles), hop, probe, decision.how)


def _merged(warnings: list[EngineWarning], outliers: int) -> list[EngineWarning]:
    """The tiles' warnings once each. A tile counts the outliers of its halo too: the outlier
    warning says the stitched count, and the tiles' "N more points the solve moved far"
    warnings (those points are among the stitched outliers) are folded into it."""
    out: dict[str, EngineWarning] = {}
    for w in warnings:
        if w.code == "outliers-moved-far":
            continue
        if w.code == "outliers":
            head, _, rest = w.message.partition(" ")
            text = f"{outliers} {rest}" if head.isdigit() else w.message
            w = warning("outliers", text, **{**w.numbers, "count": outliers})
        out.setdefault(w.message, w)
    return sorted(out.values(), key=str)


def _given_tau(geometry: Geometry, params: SmoothingParams) -> float | None:
    """A given tau, or ``rms^2 sum omega^2`` over the free points (user's weights)."""
    if params.tau_rule == "tau":
        return float(params.tau)  # type: ignore[arg-type]
    if params.tau_rule == "rms" and params.rms is not None:
        w2 = geometry.omega()[~geometry.fixed_mask()] ** 2
        return float(params.rms**2 * w2.sum())
    return None


def _unchanged(
    geometry: Geometry, params: SmoothingParams, cores: list[np.ndarray],
    decision: LambdaDecision, noise: NoiseEstimate | None, hop: float, seconds: float,
) -> TiledResult:  # fmt: skip
    """Nothing to smooth (the rule found no lambda): the input's points, bit for bit."""
    P = geometry.points.copy()
    zero = np.zeros(geometry.n)
    warnings = [] if decision.probe is None else list(decision.probe.warnings)
    result = SmoothResult(
        points=P, lam=0.0, phi=0.0, tau=None, relative_error=None, converged=True,
        iterations=0, factorizations=0, history=[], deviation=zero, rms_displacement=0.0,
        max_displacement=0.0, timings={"total": seconds}, solver="none",
        laplacian=params.laplacian, weights=params.weights, kind=geometry.kind,
        search="tiles", order=params.order, displacement=params.displacement,
        tau_rule=params.tau_rule, sigma_estimate=None if noise is None else noise.sigma,
        noise_found=None if noise is None else noise.noise_found, tau_how=decision.how,
        warnings=warnings, checks=shape_checks(geometry, P).to_dict(),
    )
    reports = [TileReport(i, int(c.size), 0, 0, "", 0.0, 0.0, 0) for i, c in enumerate(cores)]
    return TiledResult(result, reports, 0, 0, hop, 0, decision.how)
