"""The distributed backend: job records in Redis, runs on RQ workers, files in a blob store.

``GEOSMOOTH_QUEUE=rq``. The API process holds an :class:`RQQueue`; ``geosmooth worker``
processes (:mod:`service.jobs.distributed.worker`) run the jobs on any number of machines. Same
semantics
as the embedded :class:`~service.jobs.embedded.queue.LocalQueue` (statuses, progress while running,
cancel kills the run wherever it runs, time limit, TTL, retries of interrupted runs only,
idempotency, tenants, webhooks); see ``service/jobs/README.md`` for the guarantees.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from service.core.linalg.threads import threads_per_worker
from service.jobs import admit
from service.jobs.base import QueueBase
from service.jobs.config import RQConfig
from service.jobs.distributed.backend import Backend
from service.jobs.distributed.blobs import DirectoryBlobs
from service.jobs.distributed.epoch import Epoch
from service.jobs.distributed.store import RedisJobStore
from service.jobs.forkserver import prepare_forkserver
from service.jobs.notify import Notifier
from service.jobs.queue import JobQueue, JobRecord, JobStatus, NewJob, QueueHealth

if TYPE_CHECKING:
    from service.settings import Settings

__all__ = ["RQQueue"]

log = logging.getLogger("geosmooth.jobs")

_CACHE_AGE = 3600.0
_CANCEL_WAIT = 15.0
_PRUNE_INTERVAL = 600.0


class RQQueue(QueueBase[RedisJobStore]):
    """The API side of the Redis/RQ backend.

    Parameters
    ----------
    config : RQConfig
        Settings, memory limit for admission, sweep intervals
        (:class:`service.jobs.config.RQConfig`).
    backend : Backend, optional
        Connections (Redis, blob store, RQ queue); default: ``Backend.connect(config.settings)``.
    """

    def __init__(self, config: RQConfig, backend: Backend | None = None) -> None:
        backend = backend or Backend.connect(config.settings)
        self.config = config
        self.backend = backend
        self.settings = backend.settings
        self.store = backend.store
        self.blobs = backend.blobs
        self.notifier = Notifier(self.settings, backend.webhook_payload, self.store.claim_webhook,
                                 self.store.webhook_state)  # fmt: skip
        self._stop = threading.Event()
        self._sweeper: threading.Thread | None = None
        self._started = False
        self._last_reconcile = 0.0
        self._last_prune = 0.0
        self.epoch = Epoch(backend.redis, f"{backend.store.prefix}:epoch")

    @classmethod
    def from_settings(cls, settings: Settings) -> RQQueue:
        """The queue the API runs with these settings."""
        return cls(RQConfig.from_settings(settings))

    # -- life cycle ----------------------------------------------------------------------
    def start(self) -> None:
        """Start the sweeper and the webhook deliveries (Redis may still be down: the sweeper
        keeps trying; reads answer 503 meanwhile)."""
        if self._started:
            return
        self._started = True
        self._stop.clear()
        if "forkserver" in multiprocessing.get_all_start_methods():
            # the API's request processes (uploads checked at submit) fork from it: the same
            # preload and BLAS thread cap as the embedded backend's (issue 42)
            settings = self.config.settings
            prepare_forkserver(settings.threads_per_job or threads_per_worker(settings.workers))
        self.notifier.start()
        with contextlib.suppress(Exception):
            self.epoch.check()
        with contextlib.suppress(Exception):
            self.backend.remove_orphans()
        self._sweeper = threading.Thread(target=self._sweep_loop, name="geosmooth-rq-sweep",
                                         daemon=True)  # fmt: skip
        self._sweeper.start()

    def stop(self) -> None:
        """Stop the sweeper (jobs keep running on the workers)."""
        if not self._started:
            return
        self._stop.set()
        if self._sweeper is not None:
            self._sweeper.join(10.0)
        self.notifier.stop()
        self._started = False

    # -- the JobQueue protocol -----------------------------------------------------------
    def submit(self, job: NewJob) -> JobRecord:
        """See :meth:`service.jobs.queue.JobQueue.submit`."""
        row = admit.admit(job, memory_limit=self.config.memory_limit,
                          max_attempts=self.settings.max_attempts)  # fmt: skip
        with self._errors():
            if isinstance(self.blobs, DirectoryBlobs):
                admit.check_space(self.blobs.files.root, row.input_bytes,
                                  self.settings.min_free_bytes)  # fmt: skip
            self.blobs.put_input(row.job_id, row.fmt, job.input)
            rq_id = self.backend.new_rq_id(row.job_id)
            try:
                rec, created = self.store.insert(
                    row, rq_id, lambda pipe: self.backend.enqueue(row.job_id, rq_id, pipe))
            except BaseException:
                self.blobs.remove(row.job_id)
                raise
        if not created:
            self.blobs.remove(row.job_id)
            return self.get(rec.id) or rec
        return rec

    def cancel(self, job_id: str, *, tenant: str | None = None) -> JobRecord | None:
        """Cancel a queued or running job; a running job's work horse is gone on return."""
        if self.get(job_id, tenant=tenant) is None:
            return None
        with self._errors():
            raw = self.store.raw(job_id) or {}
            previous = self.store.update(
                job_id, expect=(JobStatus.QUEUED, JobStatus.RUNNING), status=JobStatus.CANCELLED,
                finished_at=time.time(), lease_until=None,
            )  # fmt: skip
            if previous is not None:
                self._stop_rq_job(raw.get("rq_job"), running=previous is JobStatus.RUNNING)
                if raw.get("webhook_url"):
                    self.notifier.enqueue(job_id)
        return self.get(job_id)

    def _stop_rq_job(self, rq_id: str | None, running: bool) -> None:
        """Drop a queued RQ job, or have its worker kill the horse and wait until it is gone."""
        if rq_id is None:
            return
        from rq.command import send_stop_job_command
        from rq.exceptions import InvalidJobOperation, NoSuchJobError
        from rq.job import Job

        redis = self.backend.redis
        try:
            job = Job.fetch(rq_id, connection=redis)
        except NoSuchJobError:
            return
        if not running:
            with contextlib.suppress(InvalidJobOperation):
                job.cancel()
            return
        with contextlib.suppress(InvalidJobOperation):
            send_stop_job_command(redis, rq_id)
        deadline = time.monotonic() + _CANCEL_WAIT
        while time.monotonic() < deadline:  # the worker reaps the horse, then marks the job
            if str(getattr(job.get_status(refresh=True), "value", "")) != "started":
                return
            time.sleep(0.05)
        log.warning("job run %s did not stop within %.0f s", rq_id, _CANCEL_WAIT)

    def result_url(self, job_id: str, fmt: str) -> str | None:
        """A presigned URL of the stored result (S3 with ``presign_seconds`` > 0)."""
        seconds = self.settings.presign_seconds
        rec = self.get(job_id)
        if not seconds or rec is None or rec.status is not JobStatus.SUCCEEDED or fmt != rec.fmt:
            return None
        from service.jobs.files import result_name

        name = f"{result_name(rec.filename, rec.id)}.{fmt}"
        return self.blobs.presign(job_id, f"result.{fmt}", seconds, name)

    def stats(self) -> dict[str, Any]:
        """Counts, queue depth and workers from Redis; the run-time histogram of every worker."""
        from rq import Worker

        counts = self._store_counts()
        with self._errors():
            workers = Worker.all(queue=self.backend.queue)
            busy = sum(1 for w in workers if w.get_state() == "busy")
            shared = self.store.histogram()
        return {
            **counts,
            "workers": len(workers),
            "busy_workers": busy,
            **shared,
        }

    def health(self) -> QueueHealth:
        """Redis reachable, blob store writable; the worker count as information."""
        checks = {"broker": "ok", "storage": self.blobs.health(), "workers": "ok"}
        try:
            self.backend.redis.ping()
            checks["broker"] = self.epoch.check()
            from rq import Worker

            if not Worker.count(queue=self.backend.queue):
                checks["workers"] = "none"  # jobs wait; the API itself is fine
        except Exception:
            checks["broker"] = "unreachable"
        if not self._started:
            checks["queue"] = "stopped"
        bad = [f"{k} {v}" for k, v in checks.items() if v != "ok" and k != "workers"]
        return QueueHealth(not bad, checks, ", ".join(bad) or None)

    # -- maintenance ---------------------------------------------------------------------
    def sweep(self) -> None:
        """One maintenance pass (see :mod:`service.jobs.distributed.backend`)."""
        backend = self.backend
        self.epoch.check()  # a Redis that came back empty is logged at once
        backend.recover()
        backend.enqueue_due()
        if time.monotonic() - self._last_reconcile >= self.config.reconcile_interval:
            self._last_reconcile = time.monotonic()
            backend.reconcile(min_age=self.config.reconcile_interval)
        backend.expire()
        for job_id in self.store.webhooks_due():
            self.notifier.enqueue(job_id)
        if time.monotonic() - self._last_prune >= _PRUNE_INTERVAL:  # a walk of the blob tree
            self._last_prune = time.monotonic()
            self.blobs.prune_cache(_CACHE_AGE)
            backend.remove_orphans()  # a lost job's blobs (Redis came back empty), 10 min old

    def _sweep_loop(self) -> None:
        while not self._stop.wait(self.config.sweep_interval):
            try:
                self.sweep()
            except Exception as exc:
                log.warning("RQ queue sweep failed: %s", exc)

    # -- hooks of QueueBase ----------------------------------------------------------------
    @contextlib.contextmanager
    def _errors(self) -> Iterator[None]:
        """Redis or blob-store failures -> ``StorageUnavailable``/``StorageFull`` (503/507)."""
        from redis.exceptions import RedisError

        from service.jobs.errors import StorageUnavailable

        try:
            with admit.storage_errors():
                yield
        except RedisError as exc:
            raise StorageUnavailable("the job broker (Redis) cannot be reached") from exc


    def _read_report(self, job_id: str) -> bytes:
        with self._errors():
            return self.backend.read_report(job_id)

    def _local_file(self, job_id: str, name: str) -> Path | None:
        return self.blobs.local_file(job_id, name)

    def _remove_files(self, job_id: str) -> None:
        with self._errors():
            self.blobs.remove(job_id)


_: type[JobQueue] = RQQueue
