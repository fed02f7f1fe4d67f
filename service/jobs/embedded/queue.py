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
  :mod:`service.jobs.child`); independently of that, every write of a run is conditional on the
  run still holding the job, so a stale process can neither record an outcome nor progress.

Recovery and housekeeping (the sweep): :mod:`service.jobs.embedded.maintenance`.
"""

from __future__ import annotations

import builtins
import dataclasses
import json
import logging
import os
import threading
import uuid
from pathlib import Path
from typing import TYPE_CHECKING, Any

from service.core.linalg.threads import threads_per_worker
from service.jobs import admit
from service.jobs.embedded.maintenance import HOST, LIVE_OWNERS, Maintenance
from service.jobs.embedded.pool import WorkerPool, default_start_method
from service.jobs.embedded.store import JobStore
from service.jobs.errors import IdempotencyConflict
from service.jobs.files import JobFiles, is_job_id
from service.jobs.limits import default_job_memory
from service.jobs.metrics import DurationHistogram
from service.jobs.notify import Notifier
from service.jobs.queue import JobQueue, JobRecord, JobStatus, NewJob, QueueHealth
from service.jobs.runner import DEFAULT_RUNNER
from service.jobs.storage_health import StorageProbe
from service.settings import default

if TYPE_CHECKING:
    from service.io import GeometryDocument
    from service.settings import Settings

__all__ = ["LocalQueue"]

log = logging.getLogger("geosmooth.jobs")


class LocalQueue(Maintenance):
    """Embedded job queue (the default backend of the service).

    Every default that is also a setting is the setting's (:func:`service.settings.default`,
    e.g. ``min_free_bytes`` 64 MiB, ``lease`` = ``worker_lease``): one place for each.

    Parameters
    ----------
    data_dir : Path
        Job store: ``jobs.sqlite3`` and ``jobs/<id>/`` (created if missing).
    workers : int, optional
        Jobs running at once, each in its own process (default: ``os.cpu_count()``).
    job_timeout : float or None
        Seconds a run may take before it is killed and the job failed (``None`` or 0: no limit).
    result_ttl : float or None
        Seconds finished jobs and their files are kept (``None`` or 0: forever).
    runner : str
        Job function ``"module:function"`` (default: the real smoothing job). Tests inject fakes.
    max_attempts : int
        Runs allowed for a job whose runs keep being interrupted.
    start_method : str, optional
        ``"forkserver"`` (default on Linux) or ``"spawn"``.
    lease : float
        Seconds without a heartbeat after which another server takes over a running job.
    kill_grace : float
        Seconds between SIGTERM and SIGKILL when killing a job.
    sweep_interval : float, optional
        Seconds between sweeps (expired results, runs of dead servers, webhooks, temp files);
        default: a quarter of ``result_ttl``, between 1 and 60 s.
    poll_interval : float
        Seconds between looks at the store when idle (jobs submitted by other processes).
    progress_interval : float
        Minimum seconds between two progress writes of a job within one stage.
    retry_backoff : float
        Seconds before an interrupted job may run again (doubled per attempt), so a burst of
        server crashes does not use up the attempts of the jobs at the head of the queue.
    memory_limit : int or None
        Per-job memory limit (bytes): refused at submit above it, ``RLIMIT_AS`` while running.
    threads_per_job : int or None
        BLAS/OpenMP threads per job process (``None``: cores / workers).
    min_free_bytes : int
        Free space a submit must leave in the store (else 507).
    reserve_bytes : int
        Size of the reserve file kept next to the database and released when the disk is full,
        so that running jobs can still be recorded as failed (0: none).
    settings : Settings, optional
        For webhook delivery (secret, SSRF policy, retries); default: from the environment.
    """

    def __init__(
        self,
        data_dir: Path | str,
        workers: int | None = None,
        job_timeout: float | None = default("job_timeout"),
        result_ttl: float | None = default("result_ttl"),
        *,
        runner: str = DEFAULT_RUNNER,
        max_attempts: int = default("max_attempts"),
        start_method: str | None = None,
        lease: float = default("worker_lease"),
        kill_grace: float = 2.0,
        sweep_interval: float | None = None,
        poll_interval: float = 0.5,
        progress_interval: float = 0.2,
        retry_backoff: float = default("retry_backoff"),
        memory_limit: int | None = None,
        threads_per_job: int | None = None,
        min_free_bytes: int = default("min_free_bytes"),
        reserve_bytes: int = default("reserve_bytes"),
        settings: Settings | None = None,
    ) -> None:
        if max_attempts < 1:
            raise ValueError("max_attempts must be >= 1")
        self.data_dir = Path(data_dir)
        self.data_dir.mkdir(parents=True, exist_ok=True)
        self.workers = int(workers or os.cpu_count() or 1)
        self.job_timeout = job_timeout or None
        self.result_ttl = result_ttl or None
        self.runner = runner
        self.max_attempts = max_attempts
        self.retry_backoff = retry_backoff
        self.memory_limit = memory_limit
        self.min_free_bytes = min_free_bytes
        self.reserve_bytes = reserve_bytes
        self.start_method = start_method or default_start_method()
        if sweep_interval is None:
            sweep_interval = min(60.0, max(1.0, (self.result_ttl or 240.0) / 4))
        self.sweep_interval = sweep_interval
        self.files = JobFiles(self.data_dir)
        self.store = JobStore(self.data_dir / "jobs.sqlite3", self.result_ttl)
        self.owner = f"{HOST}@{os.getpid()}:{uuid.uuid4().hex[:12]}"
        self.pool = WorkerPool(
            self.store, self.data_dir, self.workers, self.owner, runner, self.job_timeout,
            lease=lease, kill_grace=kill_grace, poll_interval=poll_interval,
            start_method=self.start_method, progress_interval=progress_interval,
            on_settled=self._finished, retry_backoff=retry_backoff, memory_limit=memory_limit,
            threads=threads_per_job or threads_per_worker(self.workers),
        )  # fmt: skip
        self.probe = StorageProbe(self.data_dir, min_free_bytes, self.store.check)
        self.notifier = Notifier(settings, self._webhook_payload, self.store.claim_webhook,
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
        limit = settings.job_memory_limit
        if limit is None:
            limit = default_job_memory(settings.workers)
        return cls(
            settings.data_dir,
            workers=settings.workers,
            job_timeout=settings.job_timeout,
            result_ttl=settings.result_ttl,
            max_attempts=settings.max_attempts,
            lease=settings.worker_lease,
            retry_backoff=settings.retry_backoff,
            memory_limit=limit or None,
            threads_per_job=settings.threads_per_job,
            min_free_bytes=settings.min_free_bytes,
            reserve_bytes=settings.reserve_bytes,
            settings=settings,
        )

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

    def __enter__(self) -> LocalQueue:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # -- the JobQueue protocol -----------------------------------------------------------
    def submit(self, job: NewJob) -> JobRecord:
        """Store the input durably, enqueue the job and return its ``queued`` record.

        See :meth:`service.jobs.queue.JobQueue.submit`.
        """
        row = admit.admit(job, memory_limit=self.memory_limit, max_attempts=self.max_attempts)
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
            admit.check_space(self.data_dir, row.input_bytes, self.min_free_bytes)
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

    def get(self, job_id: str, *, tenant: str | None = None) -> JobRecord | None:
        """The job's record (with its report once succeeded), ``None`` if unknown."""
        if not is_job_id(job_id):
            return None
        with admit.storage_errors():
            rec = self.store.get(job_id)
        if rec is None or (tenant is not None and rec.tenant != tenant):
            return None
        return self._with_report(rec)

    def _with_report(self, rec: JobRecord) -> JobRecord:
        if rec.status is not JobStatus.SUCCEEDED:
            return rec
        try:
            report = json.loads(self.files.report(rec.id).read_text())
        except FileNotFoundError:  # deleted or expired meanwhile
            return rec
        return dataclasses.replace(rec, report=report)

    def list(
        self,
        offset: int = 0,
        limit: int = 50,
        status: JobStatus | str | None = None,
        *,
        tenant: str | None = None,
    ) -> tuple[builtins.list[JobRecord], int]:
        """A page of jobs, newest first (records without reports), and the total count."""
        with admit.storage_errors():
            return self.store.list(offset, limit, JobStatus(status) if status else None, tenant)

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

    def delete(self, job_id: str, *, tenant: str | None = None) -> bool:
        """Delete a finished job's record and files; ``False`` if unknown or not finished."""
        if self.get(job_id, tenant=tenant) is None:
            return False
        with admit.storage_errors():
            if not self.store.delete_finished(job_id):
                return False
        self.files.remove(job_id)
        return True

    def result(self, job_id: str) -> GeometryDocument | None:
        """The input document with its geometry's points replaced by the smoothed points."""
        rec = self.get(job_id)
        if rec is None or rec.status is not JobStatus.SUCCEEDED:
            return None
        from service.jobs.results import load_result

        try:
            return load_result(self.files.input(job_id, rec.fmt),
                               self.files.result_points(job_id), rec.fmt, rec.weld)  # fmt: skip
        except FileNotFoundError:  # deleted or expired meanwhile
            return None

    def result_file(self, job_id: str, fmt: str) -> Path | None:
        """The smoothed file the worker wrote, if ``fmt`` is the input's format."""
        rec = self.get(job_id)
        if rec is None or rec.status is not JobStatus.SUCCEEDED or fmt != rec.fmt:
            return None
        path = self.files.result_file(job_id, rec.fmt)
        return path if path.exists() else None

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
        with admit.storage_errors():
            counts = self.store.counts()
        return {
            "counts": counts,
            "queue_depth": counts[JobStatus.QUEUED.value],
            "running": counts[JobStatus.RUNNING.value],
            "workers": self.workers,
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

    def _webhook_payload(self, job_id: str) -> tuple[str, dict[str, Any]] | None:
        rec = self.get(job_id)
        if rec is None or not rec.webhook_url:
            return None
        return rec.webhook_url, rec.public_dict()


_: type[JobQueue] = LocalQueue  # the protocol is implemented (checked by mypy)
