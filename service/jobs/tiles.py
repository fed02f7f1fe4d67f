"""Tiled jobs (issue 23): automatic tiling at admission, and the tiles on local processes.

* :func:`auto_tile_points`: when a job's memory estimate is above the per-job limit, the largest
  tile size (``n / 2^m``) whose tiles fit: the job process keeps the input and the stitched
  output (:data:`PARENT_BYTES_PER_POINT`), and each of its tile processes one tile with its halo
  (:data:`HALO_FACTOR` times the core, measured 1.3-2.0 on the tests' terrains).
* :func:`local_tiles`: a ``run_map`` for :func:`service.core.tiles.entry.smooth` on a process
  pool of the job's worker share (one BLAS thread each). A tile whose process dies is re-run on
  its own in a new pool (the finished tiles are kept); every finished tile reports progress
  with the tile counts, so a cancel (``RunLost`` from the progress callback) stops the pool.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import TYPE_CHECKING, Any, TypeVar

from service.core.progress import ProgressEvent
from service.jobs.queue import JobSize

if TYPE_CHECKING:
    from service.core.geometry import Geometry
    from service.core.params import SmoothingParams
    from service.core.result import SmoothResult
    from service.jobs.runner import JobContext

__all__ = [
    "HALO_FACTOR",
    "MIN_TILE_POINTS",
    "PARENT_BYTES_PER_POINT",
    "TileCounter",
    "auto_tile_points",
    "local_tiles",
    "run_smooth",
    "tile_workers",
]

T = TypeVar("T")
RunMap = Callable[[Callable[..., Any], list[tuple[Any, ...]]], list[Any]]
#: A tile's points (core + halo) per core point assumed at admission.
HALO_FACTOR = 2.0
#: Bytes per point the job process itself holds in a tiled run (input, output, tile index
#: arrays, a tile being cut): float64 coordinates twice, the mask and index arrays.
PARENT_BYTES_PER_POINT = 160
#: Smallest tile admission chooses (the halo would dominate below).
MIN_TILE_POINTS = 20_000
#: Tile re-runs after a worker died, per tile.
MAX_RETRIES = 2


def tile_workers() -> int:
    """Tile processes of this job: its thread share (``OMP_NUM_THREADS``, set by the worker
    from ``threads_per_worker``), at least 1."""
    try:
        return max(1, int(os.environ.get("OMP_NUM_THREADS", "1")))
    except ValueError:
        return 1


def auto_tile_points(
    size: JobSize, params: SmoothingParams, limit: int, workers: int = 1
) -> int | None:
    """The largest ``n / 2^m`` whose tiled run fits ``limit`` bytes (``None``: none does, or
    the parameters have no tiled form)."""
    from service.core.errors import ParameterError
    from service.core.linalg.resources import estimate_resources
    from service.core.tiles import check_tileable

    try:
        check_tileable(params)
    except ParameterError:
        return None
    tile = size.n
    while tile >= 2 * MIN_TILE_POINTS:
        tile = (tile + 1) // 2
        members = min(int(HALO_FACTOR * tile), size.n)
        faces = None if size.n_faces is None else int(size.n_faces * members / size.n)
        est = estimate_resources(members, size.dim, size.kind, params, n_faces=faces,
                                 memory_limit=limit // max(workers, 1))  # fmt: skip
        if PARENT_BYTES_PER_POINT * size.n + workers * est.memory_bytes <= limit:
            return tile
    return None


class TileCounter:
    """Tiles finished in the current round, for the progress dict's ``tiles`` member."""

    def __init__(self) -> None:
        self.done = 0
        self.total = 0
        self.rounds = 0
        self.retried = 0

    def as_dict(self) -> dict[str, int]:
        return {"done": self.done, "total": self.total, "round": self.rounds,
                "retried": self.retried}  # fmt: skip


def _init_worker() -> None:
    """One BLAS thread; killed with the job process (``PR_SET_PDEATHSIG``), so a job killed
    on timeout or cancel leaves no tile process behind."""
    import ctypes
    import signal

    from service.core.linalg.threads import limit_threads

    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    limit_threads(1)


@contextlib.contextmanager
def _may_have_children() -> Iterator[None]:
    """Let a daemonic job process start its tile pool (multiprocessing refuses children of
    daemonic processes because they could be orphaned; :func:`_init_worker` kills them with
    their parent instead)."""
    proc = multiprocessing.current_process()
    config = getattr(proc, "_config", {})
    was = config.get("daemon")
    config["daemon"] = False
    try:
        yield
    finally:
        if was is not None:
            config["daemon"] = was


@contextlib.contextmanager
def local_tiles(
    workers: int, on_tile: Callable[[], None] | None = None, counter: TileCounter | None = None
) -> Iterator[Callable[[Callable[..., T], list[tuple[Any, ...]]], list[T]]]:
    """A ``run_map`` on ``workers`` processes (module docstring); the pool ends with the
    block, its processes killed if the block is left by an exception (a cancel)."""
    ctx = multiprocessing.get_context("spawn")
    state: dict[str, ProcessPoolExecutor | None] = {"pool": None}
    count = counter or TileCounter()

    def pool() -> ProcessPoolExecutor:
        current = state["pool"]
        if current is None:
            current = ProcessPoolExecutor(workers, mp_context=ctx, initializer=_init_worker)
            state["pool"] = current
        return current

    def submit(fn: Callable[..., T], args: tuple[Any, ...]) -> Future[T]:
        with _may_have_children():  # the pool starts its processes on submit
            return pool().submit(fn, *args)

    def run_map(fn: Callable[..., T], args: list[tuple[Any, ...]]) -> list[T]:
        out: dict[int, T] = {}
        tries = dict.fromkeys(range(len(args)), 0)
        count.done, count.total, count.rounds = 0, len(args), count.rounds + 1
        todo = list(range(len(args)))
        while todo:
            futures: dict[Future[T], int] = {submit(fn, args[i]): i for i in todo}
            todo = []
            pending = set(futures)
            while pending:
                finished, pending = wait(pending, return_when=FIRST_COMPLETED)
                for fut in finished:
                    i = futures[fut]
                    try:
                        out[i] = fut.result()
                    except BrokenProcessPool:
                        tries[i] += 1
                        if tries[i] > MAX_RETRIES:
                            raise
                        todo.append(i)
                        continue
                    count.done += 1
                    if on_tile is not None:
                        on_tile()
            if todo:  # a worker died: the pool is broken, its unfinished tiles re-run alone
                _kill(state["pool"])
                state["pool"] = None
                count.retried += len(todo)
        return [out[i] for i in range(len(args))]

    try:
        yield run_map
    except BaseException:
        _kill(state["pool"])
        state["pool"] = None
        raise
    finally:
        last = state["pool"]
        if last is not None:
            last.shutdown(wait=True)


def _kill(pool: ProcessPoolExecutor | None) -> None:
    """Stop a pool now: pending tiles cancelled, running processes killed."""
    if pool is None:
        return
    procs = list(getattr(pool, "_processes", {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in procs:
        with contextlib.suppress(Exception):
            proc.kill()


def run_smooth(ctx: JobContext, geometry: Geometry) -> SmoothResult:
    """The job's smoothing: :func:`service.core.smooth`, its tiles (if any) on
    :func:`local_tiles` with the tile counts in every progress dict (``tiles`` member)."""
    from service.core.tiles.entry import smooth

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
    """RQ jobs inside a ``geosmooth worker`` (its work horses have ``GEOSMOOTH_WORKER_PID``),
    else :func:`local_tiles` on this job's worker share."""
    if os.environ.get("GEOSMOOTH_WORKER_PID"):
        from service.jobs.distributed.tiles import rq_tiles

        return rq_tiles(ctx.job_id, on_tile, counter)
    return local_tiles(tile_workers(), on_tile, counter)
