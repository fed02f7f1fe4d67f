"""What one job does, inside its worker process: read, smooth, write.

A *job function* takes a :class:`JobContext` and returns the report dict; the worker process
(:mod:`service.jobs.embedded.child`, :mod:`service.jobs.distributed.tasks`, both through
:func:`service.jobs.execute.run_function`) records the outcome. :func:`smooth_job` is the real
one; ``LocalConfig(runner="module:function")`` swaps in another (tests use fakes). The backend
gives the run its tile map (``JobContext.tiles``); nothing here picks a backend.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from service.core.progress import ProgressEvent
from service.jobs.files import write_durable
from service.jobs.progress import ProgressTracker, TileCounter

if TYPE_CHECKING:
    from service.core.geometry import Geometry
    from service.core.params import SmoothingParams
    from service.core.result import SmoothResult
    from service.jobs.tiles import RunMap, TileMap

__all__ = ["DEFAULT_RUNNER", "JobContext", "RunLost", "smooth_job"]

DEFAULT_RUNNER = "service.jobs.runner:smooth_job"


class RunLost(BaseException):
    """The run no longer holds its job (cancelled, timed out or taken over): stop quietly.

    A ``BaseException`` so that a job function's ``except Exception`` cannot swallow it.
    """


@dataclass
class JobContext:
    """Everything a job function may use.

    Attributes
    ----------
    job_id : str
        The job.
    job_dir : Path
        Its working directory (the input; outputs written with :meth:`write` are stored).
    input_path : Path
        The stored input file.
    fmt : str
        Its format.
    params : SmoothingParams
        Smoothing parameters.
    report_progress : callable
        ``(progress dict) -> bool`` writing to the job's record; ``False`` when the run lost
        its job.
    progress_interval : float
        Minimum seconds between two progress writes inside one stage (a new stage is always
        written at once, and so is the last event held back, by :meth:`flush_progress`).
    weld : bool
        Merge exactly coincident vertices when reading the input.
    memory_limit : int or None
        The per-job memory limit (bytes): the engine takes its matrix-free path when the direct
        one would not fit (the process runs under a cap of that size).
    tiles : TileMap or None
        What runs a tiled job's tiles, chosen by the backend that runs the job (local processes
        or RQ tasks); ``None``: :func:`~service.jobs.tiles.local.local_tile_map`.
    """

    job_id: str
    job_dir: Path
    input_path: Path
    fmt: str
    params: SmoothingParams
    report_progress: Callable[[dict[str, Any]], bool]
    progress_interval: float = 0.2
    weld: bool = False
    memory_limit: int | None = None
    tiles: TileMap | None = None
    _tracker: ProgressTracker = field(default_factory=ProgressTracker, repr=False)
    _started: float = field(default_factory=time.monotonic, repr=False)
    _last_write: float = field(default=float("-inf"), repr=False)
    _last_stage: str | None = field(default=None, repr=False)
    _pending: dict[str, Any] | None = field(default=None, repr=False)
    written: list[str] = field(default_factory=list, repr=False)

    def __post_init__(self) -> None:
        self._tracker.tolerance = float(self.params.tolerance)

    def progress(self, event: ProgressEvent) -> None:
        """Progress callback for :func:`service.core.smooth` (throttled within a stage).

        Raises
        ------
        RunLost
            When the job was cancelled or taken away from this run.
        """
        elapsed = time.monotonic() - self._started  # of the whole run, reading included
        data = self._tracker.update(dataclasses.replace(event, elapsed=elapsed))
        now = time.monotonic()
        if event.stage == self._last_stage and now - self._last_write < self.progress_interval:
            self._pending = data
            return
        self._write_progress(data, now)

    def stage(self, name: str) -> None:
        """Report a stage of the job function itself (``reading``, ``writing``)."""
        self.flush_progress()
        self.progress(ProgressEvent(name))

    def _write_progress(self, data: dict[str, Any], now: float) -> None:
        self._last_write, self._last_stage, self._pending = now, data["stage"], None
        if not self.report_progress(data):
            raise RunLost(self.job_id)

    def flush_progress(self) -> None:
        """Write a progress update held back by throttling."""
        if self._pending is not None:
            self._write_progress(self._pending, time.monotonic())

    def write(self, name: str, data: bytes) -> Path:
        """Write an output file into the job directory durably and atomically."""
        path = self.job_dir / name
        write_durable(path, data)
        if name not in self.written:
            self.written.append(name)
        return path


def smooth_job(ctx: JobContext) -> dict[str, Any]:
    """The real job: the use case read -> smooth -> write
    (:func:`service.workflows.smooth_file.smooth_file`) storing ``result.npy`` and
    ``result.<fmt>``.

    Parameters
    ----------
    ctx : JobContext
        The run.

    Returns
    -------
    dict
        ``SmoothResult.report()``.
    """
    from service.workflows.smooth_file import smooth_file

    def store(result: SmoothResult, data: bytes) -> None:
        buf = io.BytesIO()
        np.save(buf, np.ascontiguousarray(result.points, dtype=np.float64))
        ctx.write("result.npy", buf.getvalue())
        ctx.write(f"result.{ctx.fmt}", data)

    done = smooth_file(ctx.input_path, store, ctx.params, fmt=ctx.fmt, out_fmt=ctx.fmt,
                       read_options={"weld": ctx.weld}, stage=ctx.stage,
                       engine=lambda geometry: run_smooth(ctx, geometry))  # fmt: skip
    return done.result.report()


def run_smooth(ctx: JobContext, geometry: Geometry) -> SmoothResult:
    """The job's smoothing: :func:`service.core.smooth`, its tiles (if any) on the run's tile
    map (``ctx.tiles``) with the tile counts in every progress dict (``tiles`` member)."""
    from service.workflows.smooth_file import run_engine as smooth

    params = ctx.params
    if params.tile_points is None or geometry.n <= params.tile_points:
        return smooth(geometry, params, ctx.progress, memory_limit=ctx.memory_limit)
    counter = TileCounter()
    report = ctx.report_progress

    def with_tiles(data: dict[str, Any]) -> bool:
        return report({**data, "tiles": counter.as_dict()})

    ctx.report_progress = with_tiles
    last: dict[str, str] = {"stage": "neighborhoods"}

    def progress(event: ProgressEvent) -> None:
        last["stage"] = event.stage
        ctx.progress(event)

    def on_tile() -> None:
        ctx.progress(ProgressEvent(last["stage"]))
        ctx.flush_progress()

    try:
        with _tiles_of(ctx, on_tile, counter) as run_map:
            result = smooth(geometry, params, progress, memory_limit=ctx.memory_limit,
                            run_map=run_map)  # fmt: skip
        if result.tiles is not None:
            result.tiles["retried"] = counter.retried
        return result
    finally:
        ctx.report_progress = report


def _tiles_of(
    ctx: JobContext, on_tile: Callable[[], None], counter: TileCounter
) -> contextlib.AbstractContextManager[RunMap]:
    """The tile map the job's backend gave the run (``ctx.tiles``), else local processes."""
    from service.jobs.tiles.local import local_tile_map

    return (ctx.tiles or local_tile_map)(ctx.job_id, on_tile, counter)
