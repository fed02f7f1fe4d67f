"""The RQ task: one run of one job, inside the work horse RQ forked for it.

:func:`run_job` is what the RQ queue carries (only the job id travels through Redis). It

1. dies with its worker (``PR_SET_PDEATHSIG``): a worker killed with SIGKILL leaves no orphan
   run, so when the lease expires and the job runs elsewhere it never runs twice at once;
2. claims the job for this very RQ job (a stale duplicate, a cancelled job: nothing to do);
3. arms its time limit as a *kernel* timer with the default SIGALRM action, so a job stuck in C
   code (a CHOLMOD factorization holding the GIL) is killed on time; the worker records the
   timeout when it reaps the horse;
4. caps its address space (``RLIMIT_AS``) and BLAS threads, runs the job function in a
   workspace of the blob store (:func:`service.jobs.execute.run_function`, its tiles as RQ
   tasks: :func:`service.jobs.distributed.tiles.rq_tiles`), stores the outputs, and records
   the outcome. Input errors fail
   the job (never retried); an unreachable Redis or object store puts it back in the queue.
"""

from __future__ import annotations

import os
import signal
import time
from typing import TYPE_CHECKING, Any

from service.jobs import problems
from service.jobs.distributed.backend import HOST, WorkerConfig, worker_config
from service.jobs.distributed.tiles import rq_tiles
from service.jobs.errors import StorageUnavailable
from service.jobs.execute import RunOptions, run_function, write_report
from service.jobs.limits import limit_memory, set_parent_death_signal
from service.jobs.progress import final_progress
from service.jobs.queue import JobStatus
from service.jobs.runner import RunLost

if TYPE_CHECKING:
    from service.jobs.distributed.backend import Backend

__all__ = ["run_job"]


#: Redis refusing writes for its own reasons (out of memory, a failed save on a full disk, no
#: replica, a read-only replica): the platform's failure, not the job's.
_REDIS_REFUSALS = ("OOM", "MISCONF", "NOREPLICAS", "READONLY")


def _infrastructure(exc: BaseException) -> bool:
    """Whether a failure is the platform's, not the job's (the job is run again)."""
    from redis.exceptions import ConnectionError as RedisConnectionError
    from redis.exceptions import ResponseError
    from redis.exceptions import TimeoutError as RedisTimeoutError

    if isinstance(exc, ResponseError):
        return str(exc).split(" ", 1)[0] in _REDIS_REFUSALS
    return isinstance(exc, StorageUnavailable | RedisConnectionError | RedisTimeoutError)


def run_job(job_id: str) -> None:
    """Run one job (the RQ task; executed in the work horse)."""
    from rq import get_current_job

    set_parent_death_signal()
    worker_pid = int(os.environ.get("GEOSMOOTH_WORKER_PID", "0"))
    if worker_pid and os.getppid() != worker_pid:  # the worker died before the signal was armed
        os._exit(0)
    config = worker_config()
    backend = config.backend
    rq_job = get_current_job()
    assert rq_job is not None
    owner = str(rq_job.worker_name)
    attempt = backend.store.claim(job_id, rq_job.id, owner, backend.settings.worker_lease,
                                  os.getpid(), HOST)  # fmt: skip
    if attempt is None:
        return
    signal.signal(signal.SIGALRM, signal.SIG_DFL)  # the kernel kills the horse at the limit
    signal.setitimer(signal.ITIMER_REAL, float(backend.settings.job_timeout))
    try:
        _run(config, job_id, owner, attempt)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)


def _run(config: WorkerConfig, job_id: str, owner: str, attempt: int) -> None:
    backend = config.backend
    store, blobs = backend.store, backend.blobs
    when = {"owner": owner, "attempts": attempt}
    started = time.perf_counter()
    options = RunOptions(config.runner, config.memory_limit, 0.2, rq_tiles)

    def report_progress(progress: dict[str, Any]) -> bool:
        try:
            return store.run_update(job_id, owner, attempt, progress=progress)
        except Exception as exc:  # progress is advice: Redis refusing a write ends no run here
            if not _infrastructure(exc):
                raise
            return True  # the outcome's write, or the sweep once the lease expired, settles it

    try:
        rec = store.get(job_id)
        if rec is None or rec.status is not JobStatus.RUNNING:
            return
        limit_memory(config.memory_limit)  # threads: limited in the worker, inherited
        with blobs.workspace(job_id, rec.fmt) as workdir:
            ctx, report = run_function(rec, workdir, workdir / f"input.{rec.fmt}",
                                       report_progress, options)  # fmt: skip
            write_report(ctx, report)
            blobs.commit(job_id, workdir, ctx.written)
        _succeed(backend, job_id, owner, attempt, report, time.perf_counter() - started)
    except RunLost:
        return
    except BaseException as exc:
        if _infrastructure(exc):
            backend.requeue(job_id, when, attempt, count=True)
        else:
            backend.fail(job_id, when, problems.from_exception(exc))


def _succeed(
    backend: Backend, job_id: str, owner: str, attempt: int, report: dict[str, Any], elapsed: float
) -> None:
    done = backend.store.run_update(
        job_id, owner, attempt, status=JobStatus.SUCCEEDED, finished_at=time.time(),
        run_seconds=elapsed, progress=final_progress(report, elapsed), lease_until=None,
    )  # fmt: skip
    if done:
        backend.store.observe(elapsed)
