"""Scans larger than one job: spatial tiles with halos running the whole default (issues 23, 43).

:func:`smooth_tiled` (:mod:`.driver`) cuts the input into cores (:mod:`.partition`), makes one
noise estimate, decides one lambda with a pluggable rule on the probe tile (:mod:`.lam`), grows
each core by a halo as wide as the solution's influence reaches at it (:mod:`.halo`) and runs
the default's stages on every tile at that lambda (:mod:`.solve`).
"""

from service.core.tiles.driver import TiledResult, TileReport, check_tileable, smooth_tiled

__all__ = ["TileReport", "TiledResult", "check_tileable", "smooth_tiled"]
