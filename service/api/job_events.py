"""One log line per job event, for every queue backend: started, progress, finished, requeued.

Jobs change state in worker processes (the embedded queue's, or RQ workers on other machines),
so the server watches the queue instead: every ``interval`` seconds it reads the active jobs
(``queued`` and ``running``, through :class:`~service.jobs.queue.JobQueue`) and logs what
changed since the last look, with ``job_id``, ``tenant`` and the job's own fields:

* ``job.started``: queued -> running (``attempt``);
* ``job.progress``: a new stage, or a new lambda iteration of the search (at most one line per
  job and look);
* ``job.requeued``: running -> queued (its server or worker died);
* ``job.succeeded`` / ``job.failed`` (``code`` of the problem) / ``job.cancelled``: it left
  the active set (one ``get`` per finished job), or it is among the newest jobs, finished
  before any look saw it running.

``job.submitted``, and ``job.cancelled`` / ``job.deleted`` of the API's own requests, are logged
where they happen (with the request's ``request_id``). Several servers on one store each log the
transitions they see.
"""

from __future__ import annotations

import threading
import time
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

from service.api.http.logs import get_logger
from service.jobs.queue import JobQueue, JobRecord

__all__ = ["JobEventLog"]

log = get_logger("geosmooth.jobs")
_PAGE = 500
_RECENT = 100
_REMEMBER = 10_000


@dataclass(frozen=True)
class _Seen:
    status: str
    attempts: int
    stage: str | None
    iteration: int | None
    tenant: str | None


def _seen(record: JobRecord) -> _Seen:
    progress = record.progress or {}
    return _Seen(
        record.status.value,
        record.attempts,
        progress.get("stage"),
        progress.get("iteration"),
        record.tenant,
    )


class JobEventLog:
    """Watches a queue in a daemon thread and logs job events (see the module docstring).

    Parameters
    ----------
    queue : JobQueue
        The app's queue (started).
    interval : float
        Seconds between looks.
    """

    def __init__(self, queue: JobQueue, interval: float = 1.0) -> None:
        self.queue = queue
        self.interval = interval
        self._seen: dict[str, _Seen] = {}
        self._final: OrderedDict[str, None] = OrderedDict()  # jobs whose end was logged
        self._since = 0.0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        """Remember the active jobs (no lines for them) and start watching."""
        self._since = time.time()
        self._seen = self._active()
        self._thread = threading.Thread(target=self._run, name="geosmooth-job-events", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop watching."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(self.interval + 5)

    def _run(self) -> None:
        while not self._stop.wait(self.interval):
            try:
                self.look()
            except Exception as exc:  # the watcher must outlive a failing store
                log.warning("job.events_unavailable", error=type(exc).__name__)

    def _active(self) -> dict[str, _Seen]:
        out: dict[str, _Seen] = {}
        for status in ("queued", "running"):
            records, _ = self.queue.list(0, _PAGE, status)
            out.update({r.id: _seen(r) for r in records})
        return out

    def look(self) -> None:
        """Compare the active jobs with the last look; log the differences."""
        now = self._active()
        for job_id, seen in now.items():
            self._changed(job_id, self._seen.get(job_id), seen)
        for job_id in self._seen.keys() - now.keys():
            record = self.queue.get(job_id)
            if record is not None:  # None: deleted meanwhile (the API logged job.deleted)
                self._finished(record)
        recent, _ = self.queue.list(0, _RECENT)
        for record in recent:  # finished between two looks
            if record.finished and record.created_at >= self._since:
                self._finished(record)
        self._seen = now

    def _changed(self, job_id: str, before: _Seen | None, now: _Seen) -> None:
        fields: dict[str, Any] = {"job_id": job_id, "tenant": now.tenant}
        if before is None:
            if now.status == "running":
                log.info("job.started", attempt=now.attempts, **fields)
            return
        if before.status == "running" and now.status == "queued":
            log.info("job.requeued", attempt=before.attempts, **fields)
        elif before.status == "queued" and now.status == "running":
            log.info("job.started", attempt=now.attempts, **fields)
        elif now.status == "running" and (now.stage, now.iteration) != (
            before.stage,
            before.iteration,
        ):
            log.info("job.progress", stage=now.stage, iteration=now.iteration, **fields)

    def _finished(self, record: JobRecord) -> None:
        if record.id in self._final:
            return
        self._final[record.id] = None
        while len(self._final) > _REMEMBER:
            self._final.popitem(last=False)
        fields: dict[str, Any] = {"job_id": record.id, "tenant": record.tenant}
        if record.status.value == "failed":
            code = (record.problem or {}).get("code")
            log.info("job.failed", code=code, attempt=record.attempts, **fields)
        elif record.status.value in ("succeeded", "cancelled"):
            log.info(f"job.{record.status.value}", run_seconds=record.run_seconds, **fields)
