"""A tiled job's tiles: what runs them is the job run's caller's choice (a *tile map*).

:data:`TileMap` is ``(job_id, on_tile, counter) -> context manager of a run_map``; the runner
(:mod:`service.jobs.runner`) gets one in its :class:`~service.jobs.runner.JobContext` and never
picks one itself. :func:`service.jobs.tiles.local.local_tile_map` runs the tiles on local
processes (the embedded queue, the CLI); the distributed backend passes
:func:`service.jobs.distributed.tiles.rq_tiles` (tiles as RQ tasks on any worker).
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import AbstractContextManager
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from service.jobs.progress import TileCounter

__all__ = ["RunMap", "TileMap"]

#: ``run_map(fn, [args, ...]) -> [fn(*args), ...]`` for :func:`service.core.entry.smooth`.
RunMap = Callable[[Callable[..., Any], list[tuple[Any, ...]]], list[Any]]
#: ``(job_id, on_tile, counter) -> context manager yielding a RunMap``.
TileMap = Callable[
    [str, "Callable[[], None] | None", "TileCounter"], AbstractContextManager[RunMap]
]
