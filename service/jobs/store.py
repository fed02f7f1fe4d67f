"""SQLite job metadata, safe across threads and processes.

One connection per (process, thread), WAL journal, ``synchronous=FULL`` (a committed row
survives a crash of the process and of the machine). Every state change made by a worker is
conditional on the *run* it belongs to (``owner`` and ``attempts``), so a run that was taken
away (cancelled, timed out, requeued after its server died) can no longer write to the row.
"""

from __future__ import annotations

import builtins
import contextlib
import json
import os
import sqlite3
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from service.jobs.queue import FINISHED, JobRecord, JobStatus

__all__ = ["Claim", "JobStore", "RunningRow"]

_SCHEMA = """
CREATE TABLE IF NOT EXISTS jobs (
    seq            INTEGER PRIMARY KEY AUTOINCREMENT,
    id             TEXT NOT NULL UNIQUE,
    status         TEXT NOT NULL,
    fmt            TEXT NOT NULL,
    filename       TEXT,
    params         TEXT NOT NULL,
    input_bytes    INTEGER NOT NULL,
    created_at     REAL NOT NULL,
    updated_at     REAL NOT NULL,
    started_at     REAL,
    finished_at    REAL,
    attempts       INTEGER NOT NULL DEFAULT 0,
    max_attempts   INTEGER NOT NULL,
    owner          TEXT,
    lease_until    REAL,
    pid            INTEGER,
    iteration      INTEGER,
    lam            REAL,
    phi            REAL,
    tau            REAL,
    relative_error REAL,
    problem        TEXT,
    report         TEXT,
    run_seconds    REAL
);
CREATE INDEX IF NOT EXISTS jobs_status ON jobs (status, seq);
"""

_FINISHED = tuple(s.value for s in FINISHED)
_LIST_COLUMNS = (
    "id, status, fmt, filename, params, input_bytes, created_at, updated_at, started_at,"
    " finished_at, attempts, max_attempts, pid, iteration, lam, phi, tau, relative_error,"
    " problem, run_seconds"
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


class JobStore:
    """Job metadata in one SQLite file.

    Parameters
    ----------
    path : Path
        The database file (created with its schema if missing).
    result_ttl : float or None
        Seconds finished jobs are kept (used for ``expires_at``); ``None``: forever.
    create : bool
        Create the schema and switch to WAL (worker processes open an existing store).
    """

    def __init__(self, path: Path, result_ttl: float | None = None, *, create: bool = True) -> None:
        self.path = Path(path)
        self.result_ttl = result_ttl
        self._local = threading.local()
        self._lock = threading.Lock()
        self._all: builtins.list[sqlite3.Connection] = []
        if create:
            conn = self._conn()
            conn.execute("PRAGMA journal_mode=WAL")
            conn.executescript(_SCHEMA)

    # -- connections ---------------------------------------------------------------------
    def _conn(self) -> sqlite3.Connection:
        conn: sqlite3.Connection | None = getattr(self._local, "conn", None)
        if conn is None or getattr(self._local, "pid", None) != os.getpid():
            conn = sqlite3.connect(
                self.path, timeout=30.0, isolation_level=None, check_same_thread=False
            )
            conn.row_factory = sqlite3.Row
            conn.execute("PRAGMA synchronous=FULL")
            conn.execute("PRAGMA busy_timeout=30000")
            self._local.conn = conn
            self._local.pid = os.getpid()
            with self._lock:
                self._all.append(conn)
        return conn

    @contextmanager
    def _write(self) -> Iterator[sqlite3.Connection]:
        """A write transaction that takes the database lock up front (no upgrade deadlocks)."""
        conn = self._conn()
        conn.execute("BEGIN IMMEDIATE")
        try:
            yield conn
        except BaseException:
            conn.execute("ROLLBACK")
            raise
        conn.execute("COMMIT")

    def close(self) -> None:
        """Close every connection this object opened in this process."""
        with self._lock:
            conns, self._all = self._all, []
        for conn in conns:
            with contextlib.suppress(sqlite3.Error):  # closing is best effort
                conn.close()
        self._local = threading.local()

    # -- records -------------------------------------------------------------------------
    def _record(self, row: sqlite3.Row, with_report: bool) -> JobRecord:
        keys = row.keys()
        finished_at = row["finished_at"]
        expires = None
        if finished_at is not None and self.result_ttl is not None:
            expires = finished_at + self.result_ttl
        report = None
        if with_report and "report" in keys and row["report"]:
            report = json.loads(row["report"])
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
            attempts=row["attempts"],
            max_attempts=row["max_attempts"],
            iteration=row["iteration"],
            lam=row["lam"],
            phi=row["phi"],
            tau=row["tau"],
            relative_error=row["relative_error"],
            problem=json.loads(row["problem"]) if row["problem"] else None,
            report=report,
            run_seconds=row["run_seconds"],
            pid=row["pid"],
        )

    def insert(
        self,
        job_id: str,
        fmt: str,
        filename: str | None,
        params: dict[str, Any],
        input_bytes: int,
        max_attempts: int,
    ) -> JobRecord:
        """Add a ``queued`` job (committed, and synced to disk, when this returns)."""
        with self._write() as conn:
            now = time.time()  # inside the lock: creation times follow the queue order
            conn.execute(
                "INSERT INTO jobs (id, status, fmt, filename, params, input_bytes, created_at,"
                " updated_at, max_attempts) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (
                    job_id,
                    JobStatus.QUEUED.value,
                    fmt,
                    filename,
                    json.dumps(params),
                    input_bytes,
                    now,
                    now,
                    max_attempts,
                ),
            )
        rec = self.get(job_id)
        assert rec is not None
        return rec

    def get(self, job_id: str, with_report: bool = True) -> JobRecord | None:
        """One job, or ``None``."""
        row = self._conn().execute("SELECT * FROM jobs WHERE id = ?", (job_id,)).fetchone()
        return None if row is None else self._record(row, with_report)

    def list(
        self, offset: int = 0, limit: int = 50, status: JobStatus | None = None
    ) -> tuple[builtins.list[JobRecord], int]:
        """A page of jobs, newest first (without reports), and the total count."""
        where, args = ("WHERE status = ?", [status.value]) if status else ("", [])
        conn = self._conn()
        total = conn.execute(f"SELECT COUNT(*) FROM jobs {where}", args).fetchone()[0]
        rows = conn.execute(
            f"SELECT {_LIST_COLUMNS} FROM jobs {where} ORDER BY seq DESC LIMIT ? OFFSET ?",
            [*args, max(0, limit), max(0, offset)],
        ).fetchall()
        return [self._record(r, with_report=False) for r in rows], int(total)

    def ids(self) -> set[str]:
        """Every job id in the store."""
        return {r[0] for r in self._conn().execute("SELECT id FROM jobs")}

    def counts(self) -> dict[str, int]:
        """Number of jobs per status (every status present, zero if none)."""
        out = {s.value: 0 for s in JobStatus}
        for status, n in self._conn().execute("SELECT status, COUNT(*) FROM jobs GROUP BY status"):
            out[status] = int(n)
        return out

    # -- runs ----------------------------------------------------------------------------
    def claim(self, owner: str, lease: float) -> Claim | None:
        """Take the oldest queued job for a run of ``owner`` (atomic across processes)."""
        now = time.time()
        with self._write() as conn:
            row = conn.execute(
                "SELECT id, fmt, attempts FROM jobs WHERE status = ? ORDER BY seq LIMIT 1",
                (JobStatus.QUEUED.value,),
            ).fetchone()
            if row is None:
                return None
            attempt = row["attempts"] + 1
            conn.execute(
                "UPDATE jobs SET status = ?, attempts = ?, owner = ?, lease_until = ?,"
                " started_at = ?, updated_at = ?, pid = NULL, iteration = NULL, lam = NULL,"
                " phi = NULL, relative_error = NULL WHERE id = ?",
                (JobStatus.RUNNING.value, attempt, owner, now + lease, now, now, row["id"]),
            )
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

    def progress(
        self,
        job_id: str,
        owner: str,
        attempt: int,
        iteration: int,
        lam: float,
        phi: float,
        tau: float | None,
        relative_error: float | None,
    ) -> bool:
        """Record the latest iteration of a run; ``False`` if the run lost the job."""
        return self._update_run(
            job_id,
            owner,
            attempt,
            "iteration = ?, lam = ?, phi = ?, tau = ?, relative_error = ?",
            (iteration, lam, phi, tau, relative_error),
        )

    def succeed(
        self, job_id: str, owner: str, attempt: int, report: dict[str, Any], run_seconds: float
    ) -> bool:
        """Mark a run succeeded with its report; ``False`` if the run lost the job."""
        now = time.time()

        def num(key: str) -> Any:
            value = report.get(key)
            return value if isinstance(value, int | float) else None

        return self._update_run(
            job_id,
            owner,
            attempt,
            "status = ?, finished_at = ?, report = ?, run_seconds = ?, lam = ?, phi = ?,"
            " tau = ?, relative_error = ?, iteration = ?, lease_until = NULL",
            (
                JobStatus.SUCCEEDED.value,
                now,
                json.dumps(report),
                run_seconds,
                num("lambda"),
                num("phi"),
                num("tau"),
                num("relative_error"),
                num("iterations"),
            ),
        )

    def fail(self, job_id: str, owner: str, attempt: int, problem: dict[str, Any]) -> bool:
        """Mark a run failed with a problem; ``False`` if the run lost the job."""
        return self._update_run(
            job_id,
            owner,
            attempt,
            "status = ?, finished_at = ?, problem = ?, lease_until = NULL",
            (JobStatus.FAILED.value, time.time(), json.dumps(problem)),
        )

    def requeue(self, job_id: str, owner: str, attempt: int, count_attempt: bool) -> bool:
        """Put an interrupted run's job back in the queue (``count_attempt=False``: not a try)."""
        return self._update_run(
            job_id,
            owner,
            attempt,
            "status = ?, attempts = ?, owner = NULL, lease_until = NULL, pid = NULL",
            (JobStatus.QUEUED.value, attempt if count_attempt else attempt - 1),
        )

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

    # -- deletion ------------------------------------------------------------------------
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

    def run_seconds(self, job_id: str) -> float | None:
        """Run time recorded for a succeeded job."""
        row = (
            self._conn()
            .execute(
                "SELECT run_seconds FROM jobs WHERE id = ? AND status = ?",
                (job_id, JobStatus.SUCCEEDED.value),
            )
            .fetchone()
        )
        return None if row is None else row[0]
