"""Scans larger than one job: spatial tiles with halos and one global budget (issue 23).

:func:`smooth_tiled` (:mod:`.driver`) cuts the input into cores (:mod:`.partition`), grows each
by a halo as wide as the solution's influence reaches (:mod:`.halo`), probes and solves every
tile with :func:`service.core.smooth` (:mod:`.solve`), and meets tau over the whole input with a
coordinator that sees only scalars (:mod:`.budget`).
"""

from service.core.tiles.driver import TiledResult, TileReport, check_tileable, smooth_tiled

__all__ = ["TileReport", "TiledResult", "check_tileable", "smooth_tiled"]
