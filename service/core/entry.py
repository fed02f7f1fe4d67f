"""The public ``smooth()`` (exported as ``service.core.smooth``): untiled or tiled.

The library, the CLI, the HTTP API and the jobs call this one function: with ``tile_points``
unset, or an input of at most that many points, it is :func:`service.core.pipeline.smooth_one`;
otherwise :func:`service.core.tiles.driver.smooth_tiled`, whose tiles are listed in the result's
``tiles`` member.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

from service.core.geometry import Geometry
from service.core.operator.build import SmoothingOperator
from service.core.params import SmoothingParams
from service.core.pipeline import smooth_one
from service.core.plan import Choice, make_plan
from service.core.progress import ProgressCallback
from service.core.result import SmoothResult

if TYPE_CHECKING:  # the tiles load only for a tiled run (issue 30: start-up)
    from service.core.tiles.driver import RunMap, TiledResult

__all__ = ["smooth", "tiles_report"]


def tiles_report(tiled: TiledResult, tile_points: int) -> dict[str, Any]:
    """The ``tiles`` member of a report: count, halo, rounds and one entry per tile."""
    return {
        "count": len(tiled.tiles),
        "tile_points": tile_points,
        "halo_hops": tiled.hops,
        "hop_length": tiled.hop_length,
        "rounds": tiled.rounds,
        "tiles": [dataclasses.asdict(t) for t in tiled.tiles],
    }


def smooth(
    geometry: Geometry,
    params: SmoothingParams,
    progress: ProgressCallback | None = None,
    *,
    operator: SmoothingOperator | None = None,
    memory_limit: int | None = None,
    run_map: RunMap[Any] | None = None,
) -> SmoothResult:
    """:func:`service.core.pipeline.smooth_one`, tiled when ``params.tile_points`` is below the
    input's size (``run_map`` runs the tiles; default: one after the other in this process).

    Raises
    ------
    ParameterError, TauOutOfRange, SolverError
    """
    n_tile = params.tile_points
    if n_tile is None or geometry.n <= n_tile:
        return smooth_one(geometry, params, progress, operator=operator,
                          memory_limit=memory_limit)  # fmt: skip
    from service.core.tiles.driver import smooth_tiled

    tiled = smooth_tiled(geometry, params, n_tile, progress, run_map, memory_limit)
    per_tile = Choice("auto", "the default on every tile (core + halo) with the input's noise "
                      f"estimate; lambda {tiled.lam_how}")
    plan = dataclasses.replace(
        make_plan(geometry, params, tracks=False), data_weights=per_tile, tangential=per_tile
    )
    return dataclasses.replace(tiled.result, tiles=tiles_report(tiled, n_tile), plan=plan)
