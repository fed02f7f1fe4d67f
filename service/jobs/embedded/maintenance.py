"""Crash recovery and housekeeping of the embedded queue (the sweep), and who is alive.

A run's owner is presumed dead when its lease expired (the owner renews it every third of
``lease`` seconds), or at once when the owner ran on this host and its process is gone (or is
this very process, e.g. a container restarted with the same pid, but not a live queue of it).
"""

from __future__ import annotations

import builtins
import logging
import os
import socket
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from service.jobs import problems
from service.jobs.embedded.store import RunningRow
from service.jobs.errors import storage_error
from service.jobs.files import sole_user

if TYPE_CHECKING:
    from service.jobs.config import LocalConfig
    from service.jobs.embedded.pool import WorkerPool
    from service.jobs.embedded.store import JobStore
    from service.jobs.files import JobFiles
    from service.jobs.notify import Notifier

__all__ = [
    "HOST",
    "LIVE_OWNERS",
    "ORPHAN_AGE",
    "Maintenance",
    "owner_dead",
    "pid_alive",
    "sole_user",  # from service.jobs.files (the API's spool uses it too)
]

log = logging.getLogger("geosmooth.jobs")
HOST = socket.gethostname()
LIVE_OWNERS: set[str] = set()  # owners of the queues started in this process
ORPHAN_AGE = 600.0


def pid_alive(pid: int) -> bool:
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


def owner_dead(owner: str | None) -> bool:
    """Whether an owner is certainly gone (same host only; other hosts: lease expiry)."""
    if not owner:
        return True
    host, _, rest = owner.rpartition("@")
    pid_text = rest.partition(":")[0]
    if host != HOST or not pid_text.isdigit():
        return False
    pid = int(pid_text)
    if pid == os.getpid():
        return owner not in LIVE_OWNERS
    return not pid_alive(pid)


class Maintenance:
    """The sweep of :class:`~service.jobs.embedded.queue.LocalQueue` (a mixin: it uses the queue's
    store, files, pool and notifier)."""

    store: JobStore
    files: JobFiles
    pool: WorkerPool
    notifier: Notifier
    owner: str
    config: LocalConfig
    _stop_sweeper: threading.Event
    _last_strays: float

    def delete(self, job_id: str, *, tenant: str | None = None) -> bool:
        raise NotImplementedError

    def _finished(self, job_id: str) -> None:
        raise NotImplementedError

    # -- maintenance ---------------------------------------------------------------------
    def recover(self) -> tuple[builtins.list[str], builtins.list[str]]:
        """Requeue the runs of dead servers, and this server's runs that no slot holds once
        their lease expired (or fail them after ``max_attempts`` runs).

        A requeued job waits ``retry_backoff * 2**(attempts-1)`` seconds before it runs again.

        Returns
        -------
        requeued, failed : list of str
            Job ids.
        """
        now = time.time()
        requeued, failed = [], []
        ours = self.pool.running_ids()
        for row in self.store.running():
            if row.owner == self.owner:
                # a run of this server that no slot holds any more (its outcome could not be
                # written: a full or failing disk) once its lease expired: the owner is gone
                if row.job_id in ours or (row.lease_until or 0.0) >= now:
                    continue
            elif not self._stale(row, now):
                continue
            if row.attempts >= row.max_attempts:
                problem = problems.attempts_exhausted(row.attempts)
                if self.store.fail(row.job_id, row.owner or "", row.attempts, problem):
                    failed.append(row.job_id)
                    self._finished(row.job_id)
            elif self.store.requeue(row.job_id, row.owner or "", row.attempts, True,
                                    now + self.pool.backoff(row.attempts)):  # fmt: skip
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
        return row.lease_until is None or row.lease_until < now or owner_dead(row.owner)

    def expire(self, now: float | None = None) -> builtins.list[str]:
        """Delete finished jobs older than ``result_ttl``; returns their ids."""
        gone = []
        for job_id in self.store.expired(now):
            if self.delete(job_id):
                gone.append(job_id)
        return gone

    def sweep(self) -> None:
        """One maintenance pass: recover runs of dead servers, purge expired results, remove
        stray temp files, deliver webhooks that are due."""
        self._maintain()

    def _maintain(self, initial: bool = False) -> None:
        steps: builtins.list[Callable[[], object]] = [
            self._keep_reserve, self.recover, self.expire, self._remove_strays,
            self._webhooks_due,
        ]  # fmt: skip
        if initial:
            try:
                alone = sole_user(self.files.root)
            except OSError:  # e.g. a read-only store: leave orphans to the age rule
                alone = False
            steps.append(lambda: self._remove_orphans(0.0 if alone else ORPHAN_AGE))
        for step in steps:
            try:
                step()
            except Exception as exc:
                if storage_error(exc) is None:
                    log.exception("job store maintenance failed")
                else:  # full or read-only disk: try again at the next sweep
                    log.warning("job store maintenance postponed: %s", exc)

    def _sweep_loop(self) -> None:
        while not self._stop_sweeper.wait(self.config.sweep_interval):
            self._maintain()

    def _keep_reserve(self) -> None:
        self.store.keep_reserve(self.config.reserve_bytes, self.config.min_free_bytes)

    def _remove_orphans(self, min_age: float = ORPHAN_AGE) -> None:
        """Job directories without a record, at any age when no other live process uses the
        store (:func:`sole_user`), else older than :data:`ORPHAN_AGE`, are quarantined
        (:meth:`~service.jobs.files.JobFiles.quarantine`), never deleted: a crash between the
        input and the record leaves one, but so does a lost or replaced database (a deleted
        WAL, a restored old backup), whose directories hold accepted jobs and results."""
        known = self.store.ids()
        moved = [j for j in self.files.orphans(known, min_age) if self.files.quarantine(j)]
        if not moved:
            return
        where = self.files.quarantine_dir
        if known:
            log.warning("moved %d job director(y/ies) without a record to %s (a crash between"
                        " upload and record, or records lost with the database)", len(moved),
                        where)  # fmt: skip
        else:
            log.error("the job database holds no job but %d job director(y/ies) exist: it is new,"
                      " replaced or lost; moved them to %s, nothing deleted", len(moved),
                      where)  # fmt: skip

    def _remove_strays(self) -> None:
        if time.monotonic() - self._last_strays < ORPHAN_AGE and self._last_strays > 0:
            return  # a walk of every job directory: at start, then every 10 minutes
        self._last_strays = time.monotonic()
        for tmp in self.files.stray_temporaries(ORPHAN_AGE):
            tmp.unlink(missing_ok=True)
        self._remove_orphans(ORPHAN_AGE)  # job directories whose record is gone, not only at start

    def _migrate_v0_files(self) -> None:
        for job_id in self.store.ids():
            if self.files.legacy_weld(job_id):
                self.store.set_weld(job_id)

    def _webhooks_due(self) -> None:
        for job_id in self.store.webhooks_due():
            self.notifier.enqueue(job_id)
