"""Tiled jobs (issue 23): automatic tiling at admission, and the tiles on local processes.

* :func:`~service.jobs.limits.auto_tile_points`: when a job's memory estimate is above the
  per-job limit, the largest tile size (``n / 2^m``) whose tiles fit: the job process keeps the
  input and the stitched output (:data:`~service.jobs.limits.PARENT_BYTES_PER_POINT`), and each
  of its tile processes one tile with its halo (:data:`~service.jobs.limits.HALO_FACTOR` times
  the core, measured 1.3-2.0 on the tests' terrains).
* :func:`local_tiles`: a ``run_map`` for :func:`service.core.entry.smooth` on a process
  pool of the job's worker share (one BLAS thread each). A tile whose process dies is re-run on
  its own in a new pool (the finished tiles are kept); every finished tile reports progress
  with the tile counts, so a cancel (``RunLost`` from the progress callback) stops the pool.
"""

from __future__ import annotations

import contextlib
import multiprocessing
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import TYPE_CHECKING, Any, TypeVar

from service.jobs.progress import TileCounter

if TYPE_CHECKING:
    from service.jobs.tiles import RunMap

__all__ = ["local_tile_map", "local_tiles"]

T = TypeVar("T")
#: Tile re-runs after a worker died, per tile.
MAX_RETRIES = 2


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

    run_map.workers = workers  # type: ignore[attr-defined]  # tiles per chunk (issue 43)
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


def local_tile_map(
    job_id: str, on_tile: Callable[[], None] | None, counter: TileCounter
) -> contextlib.AbstractContextManager[RunMap]:
    """The :data:`~service.jobs.tiles.TileMap` of a job process: :func:`local_tiles` on its
    worker share (:func:`service.jobs.limits.tile_workers`)."""
    from service.jobs.limits import tile_workers

    return local_tiles(tile_workers(), on_tile, counter)


def _kill(pool: ProcessPoolExecutor | None) -> None:
    """Stop a pool now: pending tiles cancelled, running processes killed."""
    if pool is None:
        return
    procs = list(getattr(pool, "_processes", {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in procs:
        with contextlib.suppress(Exception):
            proc.kill()
