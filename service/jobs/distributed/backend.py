"""What the API, the RQ workers and their work horses share: connections, keys, the sweep.

The sweep (run by every API process of the RQ backend, once per ``sweep_interval``; every step is
a conditional Redis script, so several sweepers are safe) does what the embedded queue's sweeper
and crash recovery do:

* **lost runs**: a running job whose lease expired (its worker died: its work horse died with it,
  ``PR_SET_PDEATHSIG``) is requeued after a backoff, or failed once it used ``max_attempts``;
* **due retries**: requeued jobs whose backoff is over get a fresh RQ job (a compare-and-set on
  the record's ``rq_job``: never two RQ jobs for one run);
* **lost enqueues**: a queued job whose RQ job vanished (Redis restarted without the queue's
  list, an API killed between the two writes cannot happen: submit writes both in one MULTI) is
  enqueued again (every ``reconcile_interval``);
* **TTL**: finished jobs older than ``result_ttl``: record first, then blobs; orphan blobs
  (a record that never committed) older than 10 min are removed at start;
* **webhooks** not delivered (their deliverer died) are delivered again.
"""

from __future__ import annotations

import logging
import socket
import time
import uuid
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from service.jobs import problems
from service.jobs.base import webhook_payload, with_report
from service.jobs.distributed.blobs import BlobStore, blob_store
from service.jobs.distributed.store import RedisJobStore
from service.jobs.progress import queued_progress
from service.jobs.queue import JobRecord, JobStatus

if TYPE_CHECKING:
    from rq import Queue

    from service.settings import Settings

__all__ = [
    "LEGACY_TASK_MODULES",
    "RUN_TASK",
    "Backend",
    "WorkerConfig",
    "backoff",
    "configure_worker",
    "worker_config",
]

log = logging.getLogger("geosmooth.jobs")

#: The path RQ stores with every enqueued job.
RUN_TASK = "service.jobs.distributed.tasks.run_job"
#: Modules that held the task in earlier releases: jobs queued before an upgrade name them, and
#: the worker resolves them to :mod:`service.jobs.distributed.tasks` (``worker.make_worker``).
LEGACY_TASK_MODULES = ("service.jobs.rq_tasks",)
HOST = socket.gethostname()
_ORPHAN_AGE = 600.0
_MAX_BACKOFF = 300.0
_RQ_TIMEOUT_MARGIN = 120  # RQ's own timeout only backs up the work horse's exact SIGALRM
_ACTIVE_RQ = ("queued", "scheduled", "deferred", "started")


def backoff(base: float, attempts: int) -> float:
    """Seconds an interrupted job waits before its next run, after ``attempts`` runs."""
    return min(_MAX_BACKOFF, base * 2 ** max(0, attempts - 1))


@dataclass
class Backend:
    """Connections and settings of one RQ deployment (API side, worker side alike)."""

    settings: Settings
    redis: Any
    store: RedisJobStore
    blobs: BlobStore
    queue: Queue

    @classmethod
    def connect(cls, settings: Settings) -> Backend:
        """Connect to ``GEOSMOOTH_REDIS_URL`` and the blob store (lazily: no I/O yet)."""
        from redis import Redis
        from rq import Queue

        redis = Redis.from_url(settings.redis_url, socket_connect_timeout=5,
                               socket_keepalive=True, health_check_interval=30)  # fmt: skip
        store = RedisJobStore(redis, f"geosmooth:{settings.rq_queue_name}", settings.result_ttl)
        blobs = blob_store(settings.storage_url, settings.data_dir, settings.min_free_bytes)
        return cls(settings, redis, store, blobs, Queue(settings.rq_queue_name, connection=redis))

    def get(self, job_id: str) -> JobRecord | None:
        """A job's record, with its report (from the blob store) once succeeded."""
        rec = self.store.get(job_id)
        return None if rec is None else with_report(rec, self.read_report)

    def read_report(self, job_id: str) -> bytes:
        """The job's stored ``report.json``."""
        return self.blobs.read(job_id, "report.json")

    def webhook_payload(self, job_id: str) -> tuple[str, dict[str, Any]] | None:
        """``(url, JSON of the job)`` of a job with a webhook (the worker delivers it)."""
        return webhook_payload(self.get(job_id))

    # -- RQ jobs -------------------------------------------------------------------------
    @staticmethod
    def new_rq_id(job_id: str) -> str:
        """A fresh RQ job id for a run of ``job_id`` (each run has its own)."""
        return f"{job_id}-{uuid.uuid4().hex[:8]}"

    def enqueue(self, job_id: str, rq_id: str, pipeline: Any = None) -> None:
        """Put a run of ``job_id`` on the RQ queue (inside ``pipeline``'s MULTI, if given)."""
        timeout = int(self.settings.job_timeout) + _RQ_TIMEOUT_MARGIN
        self.queue.enqueue_call(
            RUN_TASK, args=(job_id,), job_id=rq_id, timeout=timeout, result_ttl=600,
            failure_ttl=24 * 3600, pipeline=pipeline, description=f"geosmooth job {job_id}",
        )  # fmt: skip

    def requeue(self, job_id: str, when: dict[str, Any], attempts: int, count: bool) -> bool:
        """Put a run back in the queue (after the backoff if ``count``); conditional."""
        delay = backoff(self.settings.retry_backoff, attempts) if count else 0.0
        done = self.store.update(
            job_id, expect=(JobStatus.RUNNING,), when=when, status=JobStatus.QUEUED,
            attempts=attempts if count else attempts - 1, rq_job=None, owner=None,
            lease_until=None, pid=None, host=None, not_before=time.time() + delay,
            progress=queued_progress(),
        )  # fmt: skip
        if done is not None and delay == 0:
            self.enqueue_due()
        return done is not None

    def fail(self, job_id: str, when: dict[str, Any], problem: dict[str, Any]) -> bool:
        """Fail a running job (conditional on ``when``)."""
        done = self.store.update(job_id, expect=(JobStatus.RUNNING,), when=when,
                                 status=JobStatus.FAILED, finished_at=time.time(),
                                 problem=problem, lease_until=None)  # fmt: skip
        return done is not None

    def enqueue_due(self) -> list[str]:
        """Give due requeued jobs a fresh RQ job (compare-and-set: one RQ job per run)."""
        out = []
        for job_id in self.store.pending():
            rq_id = self.new_rq_id(job_id)
            taken = self.store.update(job_id, expect=(JobStatus.QUEUED,), when={"rq_job": None},
                                      rq_job=rq_id, not_before=None)  # fmt: skip
            if taken is not None:
                self.enqueue(job_id, rq_id)
                out.append(job_id)
        return out

    # -- the sweep -----------------------------------------------------------------------
    def recover(self) -> tuple[list[str], list[str]]:
        """Requeue (or fail, out of attempts) the runs whose lease expired."""
        requeued, failed = [], []
        for run in self.store.running(before=time.time()):
            when = {"owner": run.owner, "attempts": run.attempts}
            if run.attempts >= run.max_attempts:
                if self.fail(run.job_id, when, problems.attempts_exhausted(run.attempts)):
                    failed.append(run.job_id)
            elif self.requeue(run.job_id, when, run.attempts, count=True):
                requeued.append(run.job_id)
        if requeued or failed:
            log.warning("lost runs: requeued %s, failed %s", requeued, failed)
        return requeued, failed

    def reconcile(self, min_age: float) -> list[str]:
        """Enqueue again the queued jobs whose RQ job is gone (older than ``min_age`` s)."""
        from rq.job import Job

        lost = []
        now = time.time()
        for rec in self.store.list(0, 10_000, JobStatus.QUEUED)[0]:
            raw = self.store.raw(rec.id) or {}
            rq_id = raw.get("rq_job")
            if rq_id is None or now - rec.updated_at < min_age:
                continue
            status = Job.fetch(rq_id, connection=self.redis).get_status() if Job.exists(
                rq_id, connection=self.redis) else None  # fmt: skip
            if status is None or str(getattr(status, "value", status)) not in _ACTIVE_RQ:
                new = self.new_rq_id(rec.id)
                if self.store.update(rec.id, expect=(JobStatus.QUEUED,), when={"rq_job": rq_id},
                                     rq_job=new) is not None:  # fmt: skip
                    self.enqueue(rec.id, new)
                    lost.append(rec.id)
        if lost:
            log.warning("re-enqueued %d job(s) whose RQ job was lost: %s", len(lost), lost)
        return lost

    def expire(self) -> list[str]:
        """Delete finished jobs older than ``result_ttl`` (record, then blobs)."""
        gone = []
        for job_id in self.store.expired():
            if self.store.delete_finished(job_id):
                self.blobs.remove(job_id)
                gone.append(job_id)
        return gone

    def remove_orphans(self) -> None:
        """Blobs without a record, older than 10 minutes (a submit that died half way)."""
        known = self.store.ids()
        now = time.time()
        for job_id, stamp in self.blobs.job_ids().items():
            if job_id not in known and now - stamp >= _ORPHAN_AGE:
                self.blobs.remove(job_id)


@dataclass(frozen=True)
class WorkerConfig:
    """What the work horses of this worker use: set once by :func:`configure_worker` in the
    worker before it forks (``worker.make_worker``), read by the job task and the tile task."""

    backend: Backend
    runner: str
    memory_limit: int | None


_WORKER: dict[str, WorkerConfig] = {}


def configure_worker(config: WorkerConfig) -> None:
    """Make ``config`` this process's worker configuration (inherited by its work horses)."""
    _WORKER["config"] = config


def worker_config() -> WorkerConfig:
    """This worker's configuration (only inside a ``geosmooth worker`` and its horses)."""
    config = _WORKER.get("config")
    assert config is not None, "runs in a geosmooth worker (service.jobs.distributed.worker)"
    return config
