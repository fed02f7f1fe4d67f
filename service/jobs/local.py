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

A run's owner is presumed dead when its lease expired (the owner renews it every third of
``lease`` seconds), or at once when the owner ran on this host and its process is gone (or is this
very process, e.g. a container restarted with the same pid, but not a live queue of it).
"""

from __future__ import annotations

import builtins
import dataclasses
import logging
import os
import socket
import threading
import time
import uuid
from collections import deque
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from service.jobs import problems
from service.jobs.files import JobFiles, is_job_id
from service.jobs.pool import WorkerPool, default_start_method
from service.jobs.queue import JobRecord, JobStatus
from service.jobs.runner import DEFAULT_RUNNER
from service.jobs.store import JobStore, RunningRow

if TYPE_CHECKING:
    from service.core.params import SmoothingParams
    from service.io import GeometryDocument

__all__ = ["DURATION_BUCKETS", "LocalQueue"]

log = logging.getLogger("geosmooth.jobs")

DURATION_BUCKETS: tuple[float, ...] = (
    0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0, 60.0, 120.0, 300.0, 600.0, 1800.0, 3600.0,
)  # fmt: skip
_HOST = socket.gethostname()
_LIVE_OWNERS: set[str] = set()  # owners of the queues started in this process
_ORPHAN_AGE = 600.0


def _pid_alive(pid: int) -> bool:
    """Whether a process runs (a zombie nobody reaped, e.g. under a container's PID 1, does not)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except FileNotFoundError:  # gone meanwhile, or no procfs (macOS)
        return Path("/proc/self/stat").exists() is False
    except OSError:
        return True
    return stat.rsplit(")", 1)[-1].split()[0] not in ("Z", "X")


def _owner_dead(owner: str | None) -> bool:
    """Whether an owner is certainly gone (same host only; other hosts: lease expiry)."""
    if not owner:
        return True
    host, _, rest = owner.rpartition("@")
    pid_text = rest.partition(":")[0]
    if host != _HOST or not pid_text.isdigit():
        return False
    pid = int(pid_text)
    if pid == os.getpid():
        return owner not in _LIVE_OWNERS
    return not _pid_alive(pid)


class LocalQueue:
    """Embedded job queue (the default backend of the service).

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
        Seconds between sweeps (expired results, runs of dead servers); default: a quarter of
        ``result_ttl``, between 1 and 60 s.
    poll_interval : float
        Seconds between looks at the store when idle (jobs submitted by other processes).
    progress_interval : float
        Minimum seconds between two progress writes of a job.
    """

    def __init__(
        self,
        data_dir: Path | str,
        workers: int | None = None,
        job_timeout: float | None = 3600.0,
        result_ttl: float | None = 7 * 24 * 3600.0,
        *,
        runner: str = DEFAULT_RUNNER,
        max_attempts: int = 3,
        start_method: str | None = None,
        lease: float = 15.0,
        kill_grace: float = 2.0,
        sweep_interval: float | None = None,
        poll_interval: float = 0.5,
        progress_interval: float = 0.2,
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
        self.start_method = start_method or default_start_method()
        if sweep_interval is None:
            sweep_interval = min(60.0, max(1.0, (self.result_ttl or 240.0) / 4))
        self.sweep_interval = sweep_interval
        self.files = JobFiles(self.data_dir)
        self.store = JobStore(self.data_dir / "jobs.sqlite3", self.result_ttl)
        self.owner = f"{_HOST}@{os.getpid()}:{uuid.uuid4().hex[:12]}"
        self.pool = WorkerPool(
            self.store,
            self.data_dir,
            self.workers,
            self.owner,
            runner,
            self.job_timeout,
            lease=lease,
            kill_grace=kill_grace,
            poll_interval=poll_interval,
            start_method=self.start_method,
            progress_interval=progress_interval,
            on_settled=self._on_settled,
        )
        self._metrics_lock = threading.Lock()
        self._durations: deque[float] = deque(maxlen=1000)
        self._bucket_counts = [0] * (len(DURATION_BUCKETS) + 1)
        self._duration_sum = 0.0
        self._outcomes = {s.value: 0 for s in (JobStatus.SUCCEEDED, JobStatus.FAILED,
                                                JobStatus.CANCELLED)}  # fmt: skip
        self._sweeper: threading.Thread | None = None
        self._stop_sweeper = threading.Event()
        self._started = False

    # -- life cycle ----------------------------------------------------------------------
    def start(self) -> None:
        """Recover interrupted runs, then start the worker slots and the sweeper."""
        if self._started:
            return
        # a fresh identity per start (and per process, should the object cross a fork)
        self.owner = self.pool.owner = f"{_HOST}@{os.getpid()}:{uuid.uuid4().hex[:12]}"
        _LIVE_OWNERS.add(self.owner)
        self._started = True
        self.recover()
        self.expire()
        self._remove_orphans()
        self.pool.start()
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
        if self._sweeper is not None:
            self._sweeper.join(10.0)
        _LIVE_OWNERS.discard(self.owner)
        self._started = False
        self.store.close()

    def __enter__(self) -> LocalQueue:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # -- the JobQueue protocol -----------------------------------------------------------
    def submit(
        self,
        input_bytes: bytes,
        fmt: str,
        params: SmoothingParams | dict[str, Any],
        filename: str | None = None,
        *,
        weld: bool = False,
    ) -> JobRecord:
        """Store the input durably, enqueue the job and return its ``queued`` record.

        Raises
        ------
        ValueError
            For a format name geosmooth does not know.
        pydantic.ValidationError
            For ``params`` given as a dict that is not valid :class:`SmoothingParams`.
        """
        from service.core.params import SmoothingParams

        fmt = str(fmt).lower()
        self._check_format(fmt)
        if not isinstance(params, SmoothingParams):
            params = SmoothingParams.model_validate(params)
        job_id = uuid.uuid4().hex
        data = bytes(input_bytes)
        self.files.create(job_id, fmt, data, {"weld": True} if weld else None)
        try:
            rec = self.store.insert(
                job_id,
                fmt,
                filename,
                params.model_dump(mode="json", exclude_none=True),
                len(data),
                self.max_attempts,
            )
        except BaseException:
            self.files.remove(job_id)
            raise
        self.pool.notify()
        return rec

    def get(self, job_id: str) -> JobRecord | None:
        """The job's record (with its report once succeeded), ``None`` if unknown."""
        if not is_job_id(job_id):
            return None
        return self.store.get(job_id)

    def list(
        self, offset: int = 0, limit: int = 50, status: JobStatus | str | None = None
    ) -> tuple[builtins.list[JobRecord], int]:
        """A page of jobs, newest first (records without reports), and the total count."""
        return self.store.list(offset, limit, JobStatus(status) if status else None)

    def cancel(self, job_id: str) -> JobRecord | None:
        """Cancel a queued or running job; a running job's process is killed before returning.

        A finished job is returned unchanged; ``None`` if unknown. A job running in another
        server process on the same data directory is killed by that server within
        ``poll_interval``.
        """
        if not is_job_id(job_id):
            return None
        rec, previous = self.store.cancel(job_id)
        if previous is JobStatus.RUNNING:
            self.pool.kill(job_id, "cancelled")
            rec = self.store.get(job_id)
        return rec

    def delete(self, job_id: str) -> bool:
        """Delete a finished job's record and files; ``False`` if unknown or not finished."""
        if not is_job_id(job_id) or not self.store.delete_finished(job_id):
            return False
        self.files.remove(job_id)
        return True

    def result(self, job_id: str) -> GeometryDocument | None:
        """The input document with its geometry's points replaced by the smoothed points."""
        rec = self.get(job_id)
        if rec is None or rec.status is not JobStatus.SUCCEEDED:
            return None
        from service.io import read_geometry

        try:
            points = np.load(self.files.result_points(job_id), allow_pickle=False)
            weld = bool(self.files.read_options(job_id).get("weld", False))
            doc = read_geometry(self.files.input(job_id, rec.fmt), rec.fmt, weld=weld)
        except FileNotFoundError:  # deleted or expired meanwhile
            return None
        return _with_points(doc, points)

    def result_file(self, job_id: str) -> Path | None:
        """Path of the smoothed file in the input's format (``None`` unless succeeded).

        Not part of the :class:`~service.jobs.queue.JobQueue` protocol (local backend only).
        """
        rec = self.get(job_id)
        if rec is None or rec.status is not JobStatus.SUCCEEDED:
            return None
        path = self.files.result_file(job_id, rec.fmt)
        return path if path.exists() else None

    def stats(self) -> dict[str, Any]:
        """Numbers for Prometheus.

        Returns
        -------
        dict
            ``counts`` (jobs in the store per status), ``queue_depth`` (queued jobs),
            ``running``, ``workers``, ``busy_workers`` (slots of this server running a job),
            ``finished_total`` (runs this server saw end, per outcome, monotonic since start),
            ``durations`` (run seconds of the last 1000 succeeded jobs of this server) and a
            cumulative histogram of all of them: ``duration_buckets`` (list of ``[le, count]``,
            ``le`` ending with ``inf``), ``duration_sum``, ``duration_count``.
        """
        counts = self.store.counts()
        with self._metrics_lock:
            cumulative, total = [], 0
            for le, n in zip((*DURATION_BUCKETS, float("inf")), self._bucket_counts,
                             strict=True):  # fmt: skip
                total += n
                cumulative.append([le, total])
            return {
                "counts": counts,
                "queue_depth": counts[JobStatus.QUEUED.value],
                "running": counts[JobStatus.RUNNING.value],
                "workers": self.workers,
                "busy_workers": self.pool.busy(),
                "finished_total": dict(self._outcomes),
                "durations": list(self._durations),
                "duration_buckets": cumulative,
                "duration_sum": self._duration_sum,
                "duration_count": total,
            }

    # -- maintenance ---------------------------------------------------------------------
    def recover(self) -> tuple[builtins.list[str], builtins.list[str]]:
        """Requeue the runs of dead servers (or fail them after ``max_attempts`` runs).

        Returns
        -------
        requeued, failed : list of str
            Job ids.
        """
        now = time.time()
        requeued, failed = [], []
        for row in self.store.running():
            if row.owner == self.owner or not self._stale(row, now):
                continue
            if row.attempts >= row.max_attempts:
                problem = problems.attempts_exhausted(row.attempts)
                if self.store.fail(row.job_id, row.owner or "", row.attempts, problem):
                    failed.append(row.job_id)
            elif self.store.requeue(row.job_id, row.owner or "", row.attempts, count_attempt=True):
                requeued.append(row.job_id)
        if requeued:
            log.warning("requeued %d interrupted job(s): %s", len(requeued), ", ".join(requeued))
            self.pool.notify()
        if failed:
            log.warning("gave up %d job(s) interrupted too often: %s", len(failed),
                        ", ".join(failed))  # fmt: skip
        return requeued, failed

    @staticmethod
    def _stale(row: RunningRow, now: float) -> bool:
        return row.lease_until is None or row.lease_until < now or _owner_dead(row.owner)

    def expire(self, now: float | None = None) -> builtins.list[str]:
        """Delete finished jobs older than ``result_ttl``; returns their ids."""
        gone = []
        for job_id in self.store.expired(now):
            if self.delete(job_id):
                gone.append(job_id)
        return gone

    def sweep(self) -> None:
        """One maintenance pass: recover runs of dead servers, purge expired results."""
        self.recover()
        self.expire()

    def _sweep_loop(self) -> None:
        while not self._stop_sweeper.wait(self.sweep_interval):
            try:
                self.sweep()
            except Exception:
                log.exception("job store sweep failed")

    def _remove_orphans(self) -> None:
        for job_id in self.files.orphans(self.store.ids(), _ORPHAN_AGE):
            self.files.remove(job_id)

    def _on_settled(self, job_id: str) -> None:
        rec = self.store.get(job_id, with_report=False)
        if rec is None or not rec.finished:
            return
        with self._metrics_lock:
            self._outcomes[rec.status.value] += 1
            if rec.status is JobStatus.SUCCEEDED and rec.run_seconds is not None:
                seconds = float(rec.run_seconds)
                self._durations.append(seconds)
                self._duration_sum += seconds
                index = next(
                    (i for i, le in enumerate(DURATION_BUCKETS) if seconds <= le),
                    len(DURATION_BUCKETS),
                )
                self._bucket_counts[index] += 1

    @staticmethod
    def _check_format(fmt: str) -> None:
        from service.io import FORMATS

        if fmt not in FORMATS:
            raise ValueError(f"unknown format {fmt!r}; expected one of {', '.join(FORMATS)}")


def _with_points(doc: GeometryDocument, points: np.ndarray) -> GeometryDocument:
    """A copy of ``doc`` whose geometry has ``points`` (same count and order)."""
    with_points = getattr(doc, "with_points", None)
    if callable(with_points):
        return with_points(points)  # type: ignore[no-any-return]
    geometry = dataclasses.replace(doc.geometry, points=points)  # pragma: no cover
    return dataclasses.replace(doc, geometry=geometry)  # type: ignore[type-var]  # pragma: no cover
