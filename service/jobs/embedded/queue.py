"""The embedded job queue: SQLite metadata, files on disk, worker processes; restart-safe.

Guarantees
----------
* **Accepted jobs are never lost.** ``submit`` returns only after the input file is fsynced and
  the ``queued`` row is committed (``synchronous=FULL``).
* **Interrupted runs are retried, a bounded number of times.** ``stop()`` kills running jobs and
  puts them back in the queue (that run does not count as a try). After a hard stop (SIGKILL,
  power loss) the rows stay ``running`` with the dead server as ``owner``; the next ``start()``
  (and the periodic sweep of any live server on the same data directory) puts them back in the
  queue. A run counts as a try; a job whose ``max_attempts`` runs were all interrupted is failed
  with ``attempts-exhausted`` (a poison job cannot loop forever).
* **No double runs.** Worker processes die with their server (``PR_SET_PDEATHSIG``, see
  :mod:`service.jobs.embedded.child`); independently of that, every write of a run is
  conditional on the run still holding the job, so a stale process can neither record an
  outcome nor progress.

Recovery and housekeeping (the sweep): :mod:`service.jobs.embedded.maintenance`.
"""

from __future__ import annotations

import contextlib
import logging
import os
import threading
import uuid
from pathlib import Path
from typing import TYPE_CHECKING, Any

from service.jobs import admit
from service.jobs.base import QueueBase
from service.jobs.config import LocalConfig
from service.jobs.embedded.health import StorageProbe
from service.jobs.embedded.maintenance import HOST, LIVE_OWNERS, Maintenance
from service.jobs.embedded.pool import WorkerPool
from service.jobs.embedded.sqlite import DB_NAME
from service.jobs.embedded.store import JobStore
from service.jobs.errors import IdempotencyConflict
from service.jobs.files import JobFiles
from service.jobs.metrics import DurationHistogram
from service.jobs.notify import Notifier
from service.jobs.queue import JobQueue, JobRecord, JobStatus, NewJob, QueueHealth

if TYPE_CHECKING:
    from service.settings import Settings

__all__ = ["LocalQueue"]

log = logging.getLogger("geosmooth.jobs")


class LocalQueue(QueueBase[JobStore], Maintenance):
    """Embedded job queue (the default backend of the service).

    Parameters
    ----------
    config : LocalConfig
        Store, workers, limits, timings (:class:`service.jobs.config.LocalConfig`); the service
        builds it from its settings (:meth:`from_settings`).
    """

    def __init__(self, config: LocalConfig) -> None:
        self.config = config
        self.data_dir = config.data_dir
        self.data_dir.mkdir(parents=True, exist_ok=True)
        self.files = JobFiles(self.data_dir)
        self.store = JobStore(self.data_dir / DB_NAME, config.result_ttl)
        self.owner = f"{HOST}@{os.getpid()}:{uuid.uuid4().hex[:12]}"
        self.pool = WorkerPool(config, self.store, self.owner, on_settled=self._finished)
        self.probe = StorageProbe(self.data_dir, config.min_free_bytes, self.store.check,
                                  [self.files.root], self.store.path)  # fmt: skip
        self.notifier = Notifier(config.settings, self._webhook_payload, self.store.claim_webhook,
                                 self.store.webhook_state)  # fmt: skip
        self._histogram = DurationHistogram()
        self._last_strays = 0.0
        self._lock = threading.Lock()
        self._outcomes = {s.value: 0 for s in (JobStatus.SUCCEEDED, JobStatus.FAILED,
                                                JobStatus.CANCELLED)}  # fmt: skip
        self._sweeper: threading.Thread | None = None
        self._stop_sweeper = threading.Event()
        self._started = False
        if self.store.migrated_v0:
            self._migrate_v0_files()

    @classmethod
    def from_settings(cls, settings: Settings) -> LocalQueue:
        """The queue the service runs with these settings."""
        return cls(LocalConfig.from_settings(settings))

    # -- life cycle ----------------------------------------------------------------------
    def start(self) -> None:
        """Recover interrupted runs, then start the worker slots and the sweeper.

        Maintenance that fails because the store cannot be written (a full disk) is logged and
        retried by the sweeper: the queue starts and keeps answering reads.
        """
        if self._started:
            return
        # a fresh identity per start (and per process, should the object cross a fork)
        self.owner = self.pool.owner = f"{HOST}@{os.getpid()}:{uuid.uuid4().hex[:12]}"
        LIVE_OWNERS.add(self.owner)
        self._started = True
        self._maintain(initial=True)
        self.pool.start()
        self.notifier.start()
        self._stop_sweeper.clear()
        self._sweeper = threading.Thread(target=self._sweep_loop, name="geosmooth-sweep",
                                         daemon=True)  # fmt: skip
        self._sweeper.start()

    def stop(self) -> None:
        """Stop running jobs (they go back to the queue) and the background threads."""
        if not self._started:
            return
        self._stop_sweeper.set()
        self.pool.stop()
        self.notifier.stop()
        if self._sweeper is not None:
            self._sweeper.join(10.0)
        LIVE_OWNERS.discard(self.owner)
        self._started = False
        self.store.close()

    # -- the JobQueue protocol -----------------------------------------------------------
    def submit(self, job: NewJob) -> JobRecord:
        """Store the input durably, enqueue the job and return its ``queued`` record.

        See :meth:`service.jobs.queue.JobQueue.submit`.
        """
        config = self.config
        row = admit.admit(job, memory_limit=config.memory_limit, max_attempts=config.max_attempts)
        tenant, idempotency_key, input = job.tenant, job.idempotency_key, job.input
        if idempotency_key is not None:
            with admit.storage_errors():
                earlier = self.store.find_idempotent(tenant, idempotency_key)
            if earlier is not None:
                assert row.request_hash is not None
                IdempotencyConflict.check(earlier[1], row.request_hash, idempotency_key)
                if isinstance(input, Path):
                    input.unlink(missing_ok=True)  # moved into the store: nothing to keep
                return self._with_report(earlier[0])
        with admit.storage_errors():
            admit.check_space(self.data_dir, row.input_bytes, self.config.min_free_bytes)
            try:
                self.files.create(row.job_id, row.fmt, input)
                rec, created = self.store.insert(row)
            except BaseException:
                self.files.remove(row.job_id)
                raise
        if not created:  # the same request won a race with this one
            self.files.remove(row.job_id)
            return self._with_report(rec)
        self.pool.notify()
        return rec

    def cancel(self, job_id: str, *, tenant: str | None = None) -> JobRecord | None:
        """Cancel a queued or running job; a running job's process is killed before returning.

        A finished job is returned unchanged; ``None`` if unknown. A job running in another
        server process on the same data directory is killed by that server within
        ``poll_interval``.
        """
        if self.get(job_id, tenant=tenant) is None:
            return None
        with admit.storage_errors():
            rec, previous = self.store.cancel(job_id)
        if previous is JobStatus.RUNNING:
            self.pool.kill(job_id, "cancelled")
            rec = self.store.get(job_id)
        elif previous is JobStatus.QUEUED:
            self._finished(job_id)
        return rec

    def result_url(self, job_id: str, fmt: str) -> str | None:
        """Always ``None``: the embedded queue's results are served by the API."""
        return None

    def stats(self) -> dict[str, Any]:
        """Numbers for Prometheus.

        Returns
        -------
        dict
            ``counts`` (jobs in the store per status), ``queue_depth`` (queued jobs),
            ``running``, ``workers``, ``busy_workers`` (slots of this server running a job),
            ``finished_total`` (runs this server saw end, per outcome, monotonic since start)
            and the run-time histogram of :class:`~service.jobs.metrics.DurationHistogram`.
        """
        return {
            **self._store_counts(),
            "workers": self.config.workers,
            "busy_workers": self.pool.busy(),
            "finished_total": self._finished_total(),
            **self._histogram.stats(),
        }

    def _finished_total(self) -> dict[str, int]:
        with self._lock:
            return dict(self._outcomes)

    def health(self) -> QueueHealth:
        """Storage (free space, writable), database (integrity) and whether the queue runs."""
        health = self.probe.health()
        if self._started:
            return health
        return QueueHealth(False, {**health.checks, "queue": "stopped"}, "job queue not started")

    def _finished(self, job_id: str) -> None:
        """A job reached a final state in this process: metrics, then its webhook."""
        rec = self.store.get(job_id)
        if rec is None or not rec.finished:
            return
        with self._lock:
            self._outcomes[rec.status.value] += 1
        if rec.status is JobStatus.SUCCEEDED and rec.run_seconds is not None:
            self._histogram.observe(float(rec.run_seconds))
        if rec.webhook_url:
            self.notifier.enqueue(job_id)

    # -- hooks of QueueBase ----------------------------------------------------------------
    def _errors(self) -> contextlib.AbstractContextManager[None]:
        return admit.storage_errors()

    def _read_report(self, job_id: str) -> str:
        return self.files.report(job_id).read_text()

    def _local_file(self, job_id: str, name: str) -> Path | None:
        path = self.files.dir(job_id) / name
        return path if path.exists() else None

    def _remove_files(self, job_id: str) -> None:
        self.files.remove(job_id)


_: type[JobQueue] = LocalQueue  # the protocol is implemented (checked by mypy)
