"""``geosmooth worker``: an RQ worker for the distributed backend (``GEOSMOOTH_QUEUE=rq``).

One worker runs one job at a time, each in a work horse forked for it (RQ's default ``Worker``):
a job stuck in C code can be killed. Start N of them on any number of machines; they read the
same ``GEOSMOOTH_*`` settings as ``geosmooth serve`` (Redis URL, blob store, limits).

Besides what RQ does, the worker

* renews its run's lease every ``worker_lease / 3`` seconds while the horse runs, and kills the
  horse at once if the job was cancelled or taken over (RQ's stop command does the same for a
  cancel, without the polling delay);
* records what RQ cannot know when a horse dies without recording an outcome: the time limit
  (SIGALRM, armed in the horse), a crash of the job itself (SIGSEGV, SIGABRT, ...: failed), or a
  kill from outside (the OOM killer's SIGKILL, ...: requeued after a backoff, like a server
  death, until ``max_attempts``);
* on SIGTERM/SIGINT stops the running job and puts it back in the queue without counting a try,
  then exits (``docker stop`` loses nothing and costs no attempt);
* delivers the webhooks of the jobs it finished, in the background.

Entry point for the CLI: :func:`main` (``argv`` without the ``worker`` word).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import logging
import os
import signal
import sys
import time
from typing import TYPE_CHECKING, Any

from rq import Worker

from service.core.linalg.threads import limit_threads, threads_per_worker
from service.jobs import problems
from service.jobs.config import job_memory_limit
from service.jobs.distributed.backend import (
    LEGACY_TASK_MODULES,
    Backend,
    WorkerConfig,
    configure_worker,
)
from service.jobs.distributed.tiles import TILE_TASK
from service.jobs.limits import reap_zombies
from service.jobs.notify import Notifier
from service.jobs.queue import JobStatus
from service.jobs.runner import DEFAULT_RUNNER

if TYPE_CHECKING:
    from rq.job import Job
    from rq.queue import Queue

    from service.settings import Settings

__all__ = ["GeosmoothWorker", "main", "make_worker"]

log = logging.getLogger("geosmooth.jobs")

_CRASH_SIGNALS = frozenset({signal.SIGSEGV, signal.SIGBUS, signal.SIGFPE, signal.SIGILL,
                            signal.SIGABRT, signal.SIGSYS, signal.SIGTRAP})  # fmt: skip
_PRELOAD = ("service.jobs.distributed.tasks", "service.jobs.distributed.tiles",
            "service.jobs.preload")


class GeosmoothWorker(Worker):  # type: ignore[misc]
    """RQ's forking worker with geosmooth's run bookkeeping (see the module docstring)."""

    def __init__(self, backend: Backend, name: str | None = None) -> None:
        settings = backend.settings
        super().__init__(
            [backend.queue], name=name, connection=backend.redis,
            job_monitoring_interval=max(1, int(settings.worker_lease // 3)),
            work_horse_killed_handler=self._horse_killed,
        )  # fmt: skip
        self.backend = backend
        store = backend.store
        self.notifier = Notifier(settings, backend.webhook_payload, store.claim_webhook,
                                 store.webhook_state)  # fmt: skip
        self.stopping = False  # SIGTERM/SIGINT received: exit instead of starting again

    @staticmethod
    def _job_id(job: Job) -> str:
        return str(job.args[0])

    def maintain_heartbeats(self, job: Job, execution: Any) -> None:
        """RQ's heartbeat, then the run's lease; a run that lost its job is stopped."""
        super().maintain_heartbeats(job, execution)
        store, job_id = self.backend.store, self._job_id(job)
        if job.func_name == TILE_TASK:  # a tile of a job run elsewhere: stop if the job ended
            rec = store.get(job_id)
            if rec is None or rec.status is not JobStatus.RUNNING:
                self.kill_horse()
            return
        renewed = store.update(
            job_id, expect=(JobStatus.RUNNING,), when={"owner": self.name, "rq_job": job.id},
            lease_until=time.time() + self.backend.settings.worker_lease,
        )  # fmt: skip
        if renewed is None:
            rec = store.get(job_id)
            if rec is None or rec.status is not JobStatus.QUEUED:  # cancelled or taken over
                log.info("job %s: the run lost its job, stopping it", job_id)
                self.kill_horse()

    def execute_job(self, job: Job, queue: Queue) -> None:
        """RQ's run of a job, then its webhook (in the background); children nobody waited
        for are reaped."""
        try:
            super().execute_job(job, queue)
        finally:
            reap_zombies(keep=self.horse_pid or None)
        if job.func_name == TILE_TASK:
            return
        rec = self.backend.store.get(self._job_id(job))
        if rec is not None and rec.finished and rec.webhook_url:
            self.notifier.enqueue(rec.id)

    def _horse_killed(self, job: Job, retpid: int, status: int, rusage: Any) -> None:
        """Record the end of a horse that died without recording it (see the module docstring)."""
        backend, job_id = self.backend, self._job_id(job)
        if job.func_name == TILE_TASK:  # its claim expires: the coordinator re-runs the tile
            return
        raw = backend.store.raw(job_id) or {}
        ours = (raw.get("status"), raw.get("owner"), raw.get("rq_job"))
        if ours != ("running", self.name, job.id):
            return  # cancelled (RQ's stop command) or taken over: already recorded
        when, attempts = {"owner": self.name, "attempts": raw["attempts"]}, raw["attempts"]
        sig = os.WTERMSIG(status) if os.WIFSIGNALED(status) else None
        if sig == signal.SIGALRM:
            backend.fail(job_id, when, problems.timed_out(backend.settings.job_timeout))
        elif self.stopping:
            backend.requeue(job_id, when, attempts, count=False)
        elif sig is None or sig in _CRASH_SIGNALS:
            code = -sig if sig else os.waitstatus_to_exitcode(status)
            backend.fail(job_id, when, problems.crashed(code))
        elif attempts >= raw["max_attempts"]:
            last = problems.crashed(-sig)["detail"]
            backend.fail(job_id, when, problems.attempts_exhausted(attempts, last))
        else:  # killed from outside (the OOM killer's SIGKILL): like a server death
            log.warning("job %s: work horse killed by signal %s, requeued", job_id, sig)
            backend.requeue(job_id, when, attempts, count=True)

    def request_stop(self, signum: int, frame: Any) -> None:
        """SIGTERM/SIGINT: put the running job back (not a try), then exit."""
        self.stopping = True
        super().request_stop(signum, frame)
        if self.horse_pid:
            self.kill_horse()


def make_worker(
    backend: Backend, *, name: str | None = None, runner: str = DEFAULT_RUNNER
) -> GeosmoothWorker:
    """A configured worker for ``backend`` (its work horses run ``runner``)."""
    from service.jobs.distributed import tasks as rq_tasks

    for legacy in LEGACY_TASK_MODULES:  # the task path of jobs queued by an earlier release
        sys.modules.setdefault(legacy, rq_tasks)
    configure_worker(WorkerConfig(backend, runner, job_memory_limit(backend.settings)))
    return GeosmoothWorker(backend, name)


def _threads(settings: Settings) -> int:
    """BLAS threads per job: ``GEOSMOOTH_THREADS_PER_JOB``, else cores / ``GEOSMOOTH_WORKERS``
    (the worker processes sharing this machine)."""
    return settings.threads_per_job or threads_per_worker(settings.workers)


def main(argv: list[str] | None = None) -> int:
    """Run a worker until SIGTERM/SIGINT (or, with ``--burst``, until the queue is empty).

    Returns the exit status (0: stopped normally; 2: bad arguments or settings).
    """
    ap = argparse.ArgumentParser(prog="geosmooth worker", description=__doc__.split("\n\n")[0])
    ap.add_argument("--name", help="worker name (default: host.pid.random)")
    ap.add_argument("--burst", action="store_true", help="exit when the queue is empty")
    ap.add_argument("--max-jobs", type=int, help="exit after this many jobs")
    ap.add_argument("--log-level", default="INFO")
    ap.add_argument("--runner", default=DEFAULT_RUNNER, help=argparse.SUPPRESS)  # tests only
    ns = ap.parse_args(argv)
    from service.settings import get_settings

    settings = get_settings()
    if settings.queue != "rq":
        print("geosmooth worker: set GEOSMOOTH_QUEUE=rq (and GEOSMOOTH_REDIS_URL)",
              file=sys.stderr)  # fmt: skip
        return 2
    os.environ["GEOSMOOTH_WORKER_PID"] = str(os.getpid())
    limit_threads(_threads(settings))  # inherited by every horse (a global of the libraries)
    for module in (*_PRELOAD, ns.runner.partition(":")[0]):  # loaded once, shared by every horse
        importlib.import_module(module)
    logging.basicConfig(level=ns.log_level, format="%(asctime)s %(name)s %(message)s")
    backend = Backend.connect(settings)
    while True:  # RQ quits on a lost Redis connection: wait for Redis, then work again
        worker = make_worker(backend, name=ns.name, runner=ns.runner)
        worker.notifier.start()
        try:
            worker.work(burst=ns.burst, max_jobs=ns.max_jobs, logging_level=ns.log_level,
                        with_scheduler=False)  # fmt: skip
        except Exception:
            log.exception("worker stopped")
        finally:
            worker.notifier.stop()
        if worker.stopping or ns.burst or ns.max_jobs:
            return 0
        time.sleep(1.0)
        _wait_for_redis(backend)
        with contextlib.suppress(Exception):  # its registration may have outlived the outage
            worker.register_death()


def _wait_for_redis(backend: Backend, first: float = 0.5, cap: float = 10.0) -> None:
    """Sleep until Redis answers (exponential backoff between tries)."""
    from redis.exceptions import RedisError

    delay = first
    while True:
        try:
            backend.redis.ping()
            log.warning("Redis is back: the worker starts again")
            return
        except RedisError:
            time.sleep(delay)
            delay = min(cap, delay * 2)


if __name__ == "__main__":  # python -m service.jobs.distributed.worker
    sys.exit(main())
