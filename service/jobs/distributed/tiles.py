"""A tiled job's tiles as RQ jobs on any ``geosmooth worker`` (issue 23).

The job's own run (the *coordinator*, in the work horse that took the job) gets a ``run_map``
from :func:`rq_tiles`. Each call is one round of tiles:

1. every tile's ``(function, arguments)`` goes to the blob store as ``tile-<round>-<i>.in``
   (pickled: tile geometry, parameters, lambda or tau share; the blob store is the job data's
   trusted store) and one RQ job :func:`run_tile` per tile goes on the queue;
2. whoever runs a tile first *claims* it in Redis (``SET NX`` with a lease of
   ``worker_lease`` seconds, renewed every third of it while the tile runs): a worker's horse,
   or the coordinator itself, which runs unclaimed tiles while it waits (so a job also finishes
   with one worker, the one it runs on);
3. a finished tile stores ``tile-<round>-<i>.out`` (the core's points and its scalars) and
   pushes its index to the round's completion list, which the coordinator pops (``BLPOP``);
4. a tile whose worker died loses its claim when the lease runs out: the coordinator then runs
   that tile (alone) itself; the others keep their results.

Cancel: a tile's horse is stopped by its worker's heartbeat when the job is no longer running
(:mod:`service.jobs.distributed.worker`), and queued tiles of a finished job do nothing. Redis
carries per tile one RQ job, a claim and its renewals, and one list entry; the blobs carry the
tiles' points.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import pickle
import socket
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Any, TypeVar

from service.jobs.distributed.backend import worker_config
from service.jobs.files import write_durable
from service.jobs.limits import set_parent_death_signal
from service.jobs.queue import JobStatus

if TYPE_CHECKING:
    from service.jobs.distributed.backend import Backend
    from service.jobs.progress import TileCounter

__all__ = ["TILE_TASK", "rq_tiles", "run_tile"]

T = TypeVar("T")
TILE_TASK = "service.jobs.distributed.tiles.run_tile"
#: Seconds between two checks for tiles nobody holds (claims expired, or never taken).
SCAN_INTERVAL = 0.5
#: Lifetime of a tile's keys (done flag, run count, completion list): a key written for a job
#: that no longer exists (Redis came back empty while a tile ran) expires by itself.
_KEY_TTL = 24 * 3600


def _backend() -> Backend:
    return worker_config().backend


def _key(backend: Backend, job_id: str, name: str) -> str:
    return f"geosmooth:{backend.settings.rq_queue_name}:tile:{job_id}:{name}"


def _put(backend: Backend, job_id: str, name: str, data: bytes) -> None:
    """One blob of the job (directory store: a durable file; S3: an object)."""
    blobs: Any = backend.blobs
    if hasattr(blobs, "files"):
        write_durable(blobs.files.dir(job_id) / name, data)
    else:
        blobs._put(blobs.key(job_id, name), data)


@contextlib.contextmanager
def _held(backend: Backend, claim: str, owner: str) -> Iterator[None]:
    """Renew ``claim`` every third of the lease while the block runs, release it after."""
    lease = backend.settings.worker_lease
    stop = threading.Event()

    def renew() -> None:
        while not stop.wait(lease / 3):
            backend.redis.set(claim, owner, xx=True, ex=max(1, int(lease)))

    thread = threading.Thread(target=renew, daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join()
        backend.redis.delete(claim)


def _claim(backend: Backend, claim: str, owner: str) -> bool:
    lease = max(1, int(backend.settings.worker_lease))
    return bool(backend.redis.set(claim, owner, nx=True, ex=lease))


def _run_one(backend: Backend, job_id: str, name: str, owner: str,
             task: tuple[Callable[..., Any], tuple[Any, ...]] | None = None) -> bool:
    """Run tile ``name`` if this caller wins its claim; store its result and announce it."""
    base = _key(backend, job_id, name)
    if backend.redis.exists(f"{base}:done") or not _claim(backend, f"{base}:claim", owner):
        return False
    pipe = backend.redis.pipeline()  # every run of the tile counted (tiles.retried)
    pipe.incr(f"{base}:runs")
    pipe.expire(f"{base}:runs", _KEY_TTL)
    pipe.execute()
    with _held(backend, f"{base}:claim", owner):
        fn, args = task if task is not None else pickle.loads(backend.blobs.read(job_id,
                                                                                 f"{name}.in"))
        out = fn(*args)
        if dataclasses.is_dataclass(out) and hasattr(out, "worker"):
            out = dataclasses.replace(out, worker=owner)  # type: ignore[type-var]
        _put(backend, job_id, f"{name}.out", pickle.dumps(out, protocol=5))
        round_id, _, index = name.rpartition("-")
        finished = _key(backend, job_id, f"{round_id}:finished")
        pipe = backend.redis.pipeline()  # every key a TTL: the job may be gone (Redis emptied)
        pipe.set(f"{base}:done", "1", ex=_KEY_TTL)
        pipe.rpush(finished, index)
        pipe.expire(finished, _KEY_TTL)
        pipe.execute()
    return True


def run_tile(job_id: str, name: str) -> None:
    """The RQ task of one tile (in a work horse): nothing if the job no longer runs or the
    tile is held or done elsewhere."""
    set_parent_death_signal()
    backend = _backend()
    rec = backend.store.get(job_id)
    if rec is None or rec.status is not JobStatus.RUNNING:
        return
    from service.jobs.limits import limit_memory

    limit_memory(worker_config().memory_limit)
    _run_one(backend, job_id, name, f"{socket.gethostname()} pid {os.getpid()}")


#: Tiles the coordinator puts in storage at once (the driver's chunk, issue 43).
TILES_PER_ROUND = 8


@contextlib.contextmanager
def rq_tiles(
    job_id: str, on_tile: Callable[[], None] | None, counter: TileCounter
) -> Iterator[Callable[[Callable[..., T], list[tuple[Any, ...]]], list[T]]]:
    """A ``run_map`` whose tiles run as RQ jobs (module docstring): the
    :data:`~service.jobs.tiles.TileMap` the RQ task gives its job function."""
    backend = _backend()
    owner = f"{socket.gethostname()} pid {os.getpid()} (coordinator)"

    def run_map(fn: Callable[..., T], args: list[tuple[Any, ...]]) -> list[T]:
        rnd = uuid.uuid4().hex[:10]
        names = [f"tile-{rnd}-{i}" for i in range(len(args))]
        for name, a in zip(names, args, strict=True):
            _put(backend, job_id, f"{name}.in", pickle.dumps((fn, a), protocol=5))
        timeout = int(backend.settings.job_timeout) + 30
        for name in names:
            backend.queue.enqueue_call(
                TILE_TASK, args=(job_id, name), timeout=timeout, result_ttl=60,
                failure_ttl=3600, description=f"geosmooth tile {name} of {job_id}",
            )  # fmt: skip
        count = counter
        count.done, count.total, count.rounds = 0, len(args), count.rounds + 1
        results: dict[int, T] = {}
        finished = _key(backend, job_id, f"tile-{rnd}:finished")
        last_scan = 0.0
        while len(results) < len(args):
            popped = backend.redis.blpop([finished], timeout=SCAN_INTERVAL)
            if popped is not None:
                i = int(popped[1])
                if i not in results:
                    data = backend.blobs.read(job_id, f"{names[i]}.out")
                    results[i] = pickle.loads(data)
                    count.done += 1
                    runs = backend.redis.get(f"{_key(backend, job_id, names[i])}:runs")
                    count.retried += max(0, int(runs or 1) - 1)  # every re-run, whoever ran it
                    if on_tile is not None:
                        on_tile()
                continue
            if time.monotonic() - last_scan < SCAN_INTERVAL:
                continue
            last_scan = time.monotonic()
            for i, name in enumerate(names):  # help: run one tile nobody holds
                if i in results:
                    continue
                base = _key(backend, job_id, name)
                if backend.redis.exists(f"{base}:claim"):
                    continue
                if _run_one(backend, job_id, name, owner, (fn, args[i])):
                    break  # its worker died (or it was never taken): run here, alone
        backend.redis.delete(finished, *(f"{_key(backend, job_id, n)}:runs" for n in names))
        return [results[i] for i in range(len(args))]

    run_map.workers = TILES_PER_ROUND  # type: ignore[attr-defined]  # tiles per chunk (issue 43)
    yield run_map
