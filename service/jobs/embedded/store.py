"""SQLite job metadata, safe across threads and processes (plumbing:
:mod:`service.jobs.embedded.sqlite`).

One connection per (process, thread), WAL journal, ``synchronous=FULL`` (a committed row
survives a crash of the process and of the machine). Every state change made by a worker is
conditional on the *run* it belongs to (``owner`` and ``attempts``), so a run that was taken
away (cancelled, timed out, requeued after its server died) can no longer write to the row.
"""

from __future__ import annotations

import builtins
import json
import sqlite3
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from service.jobs.admit import JobRow
from service.jobs.embedded.sqlite import Database, with_reserve
from service.jobs.errors import IdempotencyConflict
from service.jobs.progress import queued_progress
from service.jobs.queue import FINISHED, JobRecord, JobStatus

__all__ = ["Claim", "JobStore", "RunningRow"]

_MAX_OFFSET = 2**62

_FINISHED = tuple(s.value for s in FINISHED)
_LIST_COLUMNS = (
    "id, status, fmt, filename, params, input_bytes, created_at, updated_at, started_at,"
    " finished_at, attempts, max_attempts, pid, progress, problem, run_seconds, weld, tenant,"
    " webhook_url"
)


@dataclass(frozen=True)
class Claim:
    """A run handed to a worker: the job and the attempt number that identifies the run."""

    job_id: str
    fmt: str
    attempt: int


@dataclass(frozen=True)
class RunningRow:
    """A ``running`` row as seen by crash recovery."""

    job_id: str
    owner: str | None
    lease_until: float | None
    attempts: int
    max_attempts: int


class JobStore(Database):
    """Job metadata in one SQLite file.

    Parameters
    ----------
    path : Path
        The database file (created with its schema, or migrated, if needed).
    result_ttl : float or None
        Seconds finished jobs are kept (used for ``expires_at``); ``None``: forever.
    create : bool
        Create or migrate the schema and switch to WAL (worker processes open an existing store).
    """

    def __init__(self, path: Path, result_ttl: float | None = None, *, create: bool = True) -> None:
        self.result_ttl = result_ttl
        super().__init__(path, create=create)

    def check(self) -> str:
        """``"ok"``, or ``"corrupt"`` when SQLite's quick check finds damage."""
        try:
            rows = self._conn().execute("PRAGMA quick_check").fetchall()
        except sqlite3.DatabaseError as exc:
            return "unavailable" if isinstance(exc, sqlite3.OperationalError) else "corrupt"
        return "ok" if [r[0] for r in rows] == ["ok"] else "corrupt"

    # -- records -------------------------------------------------------------------------
    def _record(self, row: sqlite3.Row) -> JobRecord:
        finished_at = row["finished_at"]
        expires = None
        if finished_at is not None and self.result_ttl is not None:
            expires = finished_at + self.result_ttl
        return JobRecord(
            id=row["id"],
            status=JobStatus(row["status"]),
            fmt=row["fmt"],
            filename=row["filename"],
            params=json.loads(row["params"]),
            input_bytes=row["input_bytes"],
            created_at=row["created_at"],
            updated_at=row["updated_at"],
            started_at=row["started_at"],
            finished_at=finished_at,
            expires_at=expires,
            weld=bool(row["weld"]),
            tenant=row["tenant"],
            webhook_url=row["webhook_url"],
            attempts=row["attempts"],
            max_attempts=row["max_attempts"],
            progress=json.loads(row["progress"]) if row["progress"] else None,
            problem=json.loads(row["problem"]) if row["problem"] else None,
            run_seconds=row["run_seconds"],
            pid=row["pid"],
        )

    def find_idempotent(
        self, tenant: str | None, key: str
    ) -> tuple[JobRecord, str | None] | None:
        """The job submitted earlier with this tenant and key, and its request hash."""
        row = (
            self._conn()
            .execute(
                "SELECT * FROM jobs WHERE COALESCE(tenant, '') = ? AND idempotency_key = ?",
                (tenant or "", key),
            )
            .fetchone()
        )
        return None if row is None else (self._record(row), row["request_hash"])

    def insert(self, job: JobRow) -> tuple[JobRecord, bool]:
        """Add a ``queued`` job (committed, and synced to disk, when this returns).

        Returns
        -------
        record : JobRecord
            The new job, or the earlier job with the same tenant, idempotency key and request.
        created : bool
            Whether ``record`` is new.

        Raises
        ------
        IdempotencyConflict
            The key was used for a different request.
        """
        with self._write() as conn:
            if job.idempotency_key is not None:
                earlier = self.find_idempotent(job.tenant, job.idempotency_key)
                if earlier is not None:
                    IdempotencyConflict.check(earlier[1], job.request_hash, job.idempotency_key)
                    return earlier[0], False
            now = time.time()  # inside the lock: creation times follow the queue order
            conn.execute(
                "INSERT INTO jobs (id, status, fmt, filename, params, input_bytes, created_at,"
                " updated_at, max_attempts, weld, tenant, webhook_url, idempotency_key,"
                " request_hash, progress) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (
                    job.job_id, JobStatus.QUEUED.value, job.fmt, job.filename,
                    json.dumps(job.params), job.input_bytes, now, now, job.max_attempts,
                    int(job.weld), job.tenant, job.webhook_url, job.idempotency_key,
                    job.request_hash, json.dumps(queued_progress()),
                ),
            )  # fmt: skip
        rec = self.get(job.job_id)
        assert rec is not None
        return rec, True

    def get(self, job_id: str) -> JobRecord | None:
        """One job (without its report, which lives in the job's files), or ``None``."""
        row = self._conn().execute("SELECT * FROM jobs WHERE id = ?", (job_id,)).fetchone()
        return None if row is None else self._record(row)

    def list(
        self,
        offset: int = 0,
        limit: int = 50,
        status: JobStatus | None = None,
        tenant: str | None = None,
    ) -> tuple[builtins.list[JobRecord], int]:
        """A page of jobs, newest first, and the total count (``tenant=None``: every tenant)."""
        clauses, args = [], []
        if status is not None:
            clauses.append("status = ?")
            args.append(status.value)
        if tenant is not None:
            clauses.append("tenant = ?")
            args.append(tenant)
        where = f"WHERE {' AND '.join(clauses)}" if clauses else ""
        conn = self._conn()
        total = conn.execute(f"SELECT COUNT(*) FROM jobs {where}", args).fetchone()[0]
        rows = conn.execute(
            f"SELECT {_LIST_COLUMNS} FROM jobs {where} ORDER BY seq DESC LIMIT ? OFFSET ?",
            [*args, min(max(0, limit), _MAX_OFFSET), min(max(0, offset), _MAX_OFFSET)],
        ).fetchall()
        return [self._record(r) for r in rows], int(total)

    def ids(self) -> set[str]:
        """Every job id in the store."""
        return {r[0] for r in self._conn().execute("SELECT id FROM jobs")}

    def counts(self) -> dict[str, int]:
        """Number of jobs per status (every status present, zero if none)."""
        out = {s.value: 0 for s in JobStatus}
        for status, n in self._conn().execute("SELECT status, COUNT(*) FROM jobs GROUP BY status"):
            out[status] = int(n)
        return out

    def set_weld(self, job_id: str) -> None:
        """Mark a job's input as read with ``weld`` (migration of version-0 data dirs)."""
        with self._write() as conn:
            conn.execute("UPDATE jobs SET weld = 1 WHERE id = ?", (job_id,))

    # -- runs ----------------------------------------------------------------------------
    def claim(self, owner: str, lease: float) -> Claim | None:
        """Take the oldest queued job that is due, for a run of ``owner`` (atomic)."""
        now = time.time()
        with self._write() as conn:
            row = conn.execute(
                "SELECT id, fmt, attempts FROM jobs WHERE status = ?"
                " AND (not_before IS NULL OR not_before <= ?) ORDER BY seq LIMIT 1",
                (JobStatus.QUEUED.value, now),
            ).fetchone()
            if row is None:
                return None
            attempt = row["attempts"] + 1
            conn.execute(
                "UPDATE jobs SET status = ?, attempts = ?, owner = ?, lease_until = ?,"
                " started_at = ?, updated_at = ?, pid = NULL, not_before = NULL, progress = ?"
                " WHERE id = ?",
                (JobStatus.RUNNING.value, attempt, owner, now + lease, now, now,
                 json.dumps(queued_progress("reading")), row["id"]),
            )  # fmt: skip
        return Claim(row["id"], row["fmt"], attempt)

    def _update_run(self, job_id: str, owner: str, attempt: int, sets: str, args: tuple) -> bool:
        with self._write() as conn:
            cur = conn.execute(
                f"UPDATE jobs SET {sets}, updated_at = ? WHERE id = ? AND status = ?"
                " AND owner = ? AND attempts = ?",
                (*args, time.time(), job_id, JobStatus.RUNNING.value, owner, attempt),
            )
            return cur.rowcount == 1

    def owns(self, job_id: str, owner: str, attempt: int) -> bool:
        """Whether the run ``(owner, attempt)`` still holds the job (it is running for it)."""
        row = (
            self._conn()
            .execute(
                "SELECT 1 FROM jobs WHERE id = ? AND status = ? AND owner = ? AND attempts = ?",
                (job_id, JobStatus.RUNNING.value, owner, attempt),
            )
            .fetchone()
        )
        return row is not None

    def set_pid(self, job_id: str, owner: str, attempt: int, pid: int) -> bool:
        """Record the worker process of a run."""
        return self._update_run(job_id, owner, attempt, "pid = ?", (pid,))

    def renew(self, job_id: str, owner: str, attempt: int, lease: float) -> bool:
        """Extend the lease of a run; ``False`` if the run lost the job (cancelled, taken over)."""
        return self._update_run(job_id, owner, attempt, "lease_until = ?", (time.time() + lease,))

    def progress(self, job_id: str, owner: str, attempt: int, progress: dict[str, Any]) -> bool:
        """Record the progress of a run; ``False`` if the run lost the job."""
        return self._update_run(job_id, owner, attempt, "progress = ?", (json.dumps(progress),))

    @with_reserve
    def succeed(
        self, job_id: str, owner: str, attempt: int, progress: dict[str, Any], run_seconds: float
    ) -> bool:
        """Mark a run succeeded (its final progress); ``False`` if the run lost the job."""
        return self._update_run(
            job_id,
            owner,
            attempt,
            "status = ?, finished_at = ?, run_seconds = ?, progress = ?, lease_until = NULL",
            (JobStatus.SUCCEEDED.value, time.time(), run_seconds, json.dumps(progress)),
        )

    @with_reserve
    def fail(self, job_id: str, owner: str, attempt: int, problem: dict[str, Any]) -> bool:
        """Mark a run failed with a problem; ``False`` if the run lost the job."""
        return self._update_run(
            job_id,
            owner,
            attempt,
            "status = ?, finished_at = ?, problem = ?, lease_until = NULL",
            (JobStatus.FAILED.value, time.time(), json.dumps(problem)),
        )

    @with_reserve
    def requeue(
        self,
        job_id: str,
        owner: str,
        attempt: int,
        count_attempt: bool,
        not_before: float | None = None,
    ) -> bool:
        """Put an interrupted run's job back in the queue (``count_attempt=False``: not a try).

        ``not_before``: the job is not claimed before this time (retry backoff).
        """
        return self._update_run(
            job_id,
            owner,
            attempt,
            "status = ?, attempts = ?, owner = NULL, lease_until = NULL, pid = NULL,"
            " not_before = ?, progress = ?",
            (JobStatus.QUEUED.value, attempt if count_attempt else attempt - 1, not_before,
             json.dumps(queued_progress())),
        )  # fmt: skip

    @with_reserve
    def cancel(self, job_id: str) -> tuple[JobRecord | None, JobStatus | None]:
        """Cancel a queued or running job.

        Returns
        -------
        record : JobRecord or None
            The job after the call (``None`` if unknown).
        previous : JobStatus or None
            Its status before the call if it was cancelled by this call, else ``None``.
        """
        now = time.time()
        with self._write() as conn:
            row = conn.execute("SELECT status FROM jobs WHERE id = ?", (job_id,)).fetchone()
            previous = None
            if row is not None and row["status"] in (JobStatus.QUEUED, JobStatus.RUNNING):
                previous = JobStatus(row["status"])
                conn.execute(
                    "UPDATE jobs SET status = ?, finished_at = ?, updated_at = ?,"
                    " lease_until = NULL WHERE id = ?",
                    (JobStatus.CANCELLED.value, now, now, job_id),
                )
        return self.get(job_id), previous

    def running(self) -> builtins.list[RunningRow]:
        """Every ``running`` row (for crash recovery)."""
        rows = self._conn().execute(
            "SELECT id, owner, lease_until, attempts, max_attempts FROM jobs WHERE status = ?",
            (JobStatus.RUNNING.value,),
        )
        return [RunningRow(r[0], r[1], r[2], r[3], r[4]) for r in rows]

    # -- webhooks ------------------------------------------------------------------------
    def claim_webhook(self, job_id: str, stale_after: float) -> bool:
        """Take the delivery of a finished job's webhook (one deliverer at a time).

        A delivery claimed more than ``stale_after`` seconds ago (its deliverer died) can be
        taken again.
        """
        now = time.time()
        with self._write() as conn:
            cur = conn.execute(
                f"UPDATE jobs SET webhook_state = ? WHERE id = ? AND webhook_url IS NOT NULL"
                f" AND status IN ({','.join('?' * len(_FINISHED))}) AND (webhook_state IS NULL"
                " OR (webhook_state LIKE 'sending:%'"
                " AND CAST(substr(webhook_state, 9) AS REAL) < ?))",
                (f"sending:{now}", job_id, *_FINISHED, now - stale_after),
            )
            return cur.rowcount == 1

    @with_reserve
    def webhook_state(self, job_id: str, state: str) -> None:
        """Record the outcome of a delivery: ``delivered`` or ``failed``."""
        with self._write() as conn:
            conn.execute("UPDATE jobs SET webhook_state = ? WHERE id = ?", (state, job_id))

    def webhooks_due(self) -> builtins.list[str]:
        """Finished jobs whose webhook was never delivered nor given up (e.g. the process
        that finished them died before delivering)."""
        rows = self._conn().execute(
            f"SELECT id FROM jobs WHERE webhook_url IS NOT NULL AND status IN"
            f" ({','.join('?' * len(_FINISHED))}) AND (webhook_state IS NULL"
            " OR webhook_state LIKE 'sending:%') ORDER BY seq",
            _FINISHED,
        )
        return [r[0] for r in rows]

    # -- deletion ------------------------------------------------------------------------
    @with_reserve
    def delete_finished(self, job_id: str) -> bool:
        """Delete a finished job's row; ``False`` if unknown or not finished."""
        with self._write() as conn:
            cur = conn.execute(
                f"DELETE FROM jobs WHERE id = ? AND status IN ({','.join('?' * len(_FINISHED))})",
                (job_id, *_FINISHED),
            )
            return cur.rowcount == 1

    def expired(self, now: float | None = None) -> builtins.list[str]:
        """Finished jobs older than ``result_ttl``."""
        if self.result_ttl is None:
            return []
        cutoff = (time.time() if now is None else now) - self.result_ttl
        rows = self._conn().execute(
            f"SELECT id FROM jobs WHERE status IN ({','.join('?' * len(_FINISHED))})"
            " AND finished_at < ?",
            (*_FINISHED, cutoff),
        )
        return [r[0] for r in rows]

