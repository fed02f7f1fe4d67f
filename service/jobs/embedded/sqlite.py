"""SQLite plumbing of the job store: schema versions and migrations, one connection per (process,
thread), write transactions, and the reserve file that lets outcomes be written on a full disk.

Schema 1 (this release) keeps a job's state in its row plus its files: progress is one JSON
column, the report lives in ``report.json``, ``weld`` is a column. Version 0 (before tenants and
webhooks) is migrated on open: columns added, the five progress columns folded into ``progress``,
the ``report`` column dropped (``report.json`` held it too); ``options.json`` files are folded
into ``weld`` by the queue, which knows the files.
"""

from __future__ import annotations

import builtins
import contextlib
import functools
import logging
import os
import sqlite3
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

from service.jobs.errors import StoreDamaged

__all__ = ["DB_NAME", "RESERVE_NAME", "Database", "check_file", "with_reserve"]

log = logging.getLogger("geosmooth.jobs")

_SCHEMA_VERSION = 1
_SCHEMA = """
CREATE TABLE IF NOT EXISTS jobs (
    seq             INTEGER PRIMARY KEY AUTOINCREMENT,
    id              TEXT NOT NULL UNIQUE,
    status          TEXT NOT NULL,
    fmt             TEXT NOT NULL,
    filename        TEXT,
    params          TEXT NOT NULL,
    input_bytes     INTEGER NOT NULL,
    created_at      REAL NOT NULL,
    updated_at      REAL NOT NULL,
    started_at      REAL,
    finished_at     REAL,
    attempts        INTEGER NOT NULL DEFAULT 0,
    max_attempts    INTEGER NOT NULL,
    owner           TEXT,
    lease_until     REAL,
    pid             INTEGER,
    problem         TEXT,
    run_seconds     REAL,
    weld            INTEGER NOT NULL DEFAULT 0,
    tenant          TEXT,
    webhook_url     TEXT,
    idempotency_key TEXT,
    request_hash    TEXT,
    not_before      REAL,
    progress        TEXT,
    webhook_state   TEXT
);
CREATE INDEX IF NOT EXISTS jobs_status ON jobs (status, seq);
CREATE INDEX IF NOT EXISTS jobs_tenant ON jobs (tenant, seq);
CREATE UNIQUE INDEX IF NOT EXISTS jobs_idempotency ON jobs (COALESCE(tenant, ''), idempotency_key)
    WHERE idempotency_key IS NOT NULL;
"""
# version 0 (before tenants): progress in five columns, the report in the row (and in
# report.json), weld in options.json next to the input.
_V0_ADDED = (
    "weld INTEGER NOT NULL DEFAULT 0", "tenant TEXT", "webhook_url TEXT", "idempotency_key TEXT",
    "request_hash TEXT", "not_before REAL", "progress TEXT", "webhook_state TEXT",
)  # fmt: skip
_V0_DROPPED = ("iteration", "lam", "phi", "tau", "relative_error", "report")
_V0_PROGRESS = (
    "UPDATE jobs SET progress = json_object('stage', CASE status WHEN 'succeeded' THEN 'done'"
    " ELSE 'search' END, 'iteration', iteration, 'lambda', lam, 'phi', phi, 'tau', tau,"
    " 'relative_error', relative_error, 'percent', NULL, 'eta_seconds', NULL,"
    " 'elapsed_seconds', NULL) WHERE iteration IS NOT NULL"
)
_F = TypeVar("_F", bound=Callable[..., Any])
RESERVE_NAME = "jobs.reserve"
#: The job database's file name in the data directory.
DB_NAME = "jobs.sqlite3"


def check_file(path: Path) -> None:
    """Raise :class:`StoreDamaged` unless ``path`` is missing, empty or passes SQLite's
    ``quick_check`` (a truncated, zeroed or garbled file; issue 42).

    Read-only: nothing is created, migrated or checkpointed.
    """
    if not path.exists() or path.stat().st_size == 0:
        return
    try:
        conn = sqlite3.connect(path, timeout=30.0, isolation_level=None)
        try:
            rows = [r[0] for r in conn.execute("PRAGMA quick_check").fetchall()]
        finally:
            conn.close()
    except sqlite3.OperationalError:  # locked, unreadable: not a verdict on the content
        return
    except sqlite3.DatabaseError as exc:
        rows = [str(exc)]
    if rows != ["ok"]:
        detail = "; ".join(rows[:3])[:200]
        raise StoreDamaged(
            f"the job database {path.name} is damaged ({detail}); the server does not start on"
            " it: restore it from a backup, or move it aside to start with a new one (job"
            " directories without a record are then quarantined, never deleted)",
            field="GEOSMOOTH_DATA_DIR",
        )


def with_reserve(method: _F) -> _F:
    """Retry a state change once after releasing the store's reserve when the disk is full.

    The reserve is a file the server keeps next to the database (:meth:`Database.keep_reserve`);
    without it a full disk would leave runs ``running`` (their outcome cannot be written).
    """

    @functools.wraps(method)
    def wrapper(self: Database, *args: Any, **kwargs: Any) -> Any:
        try:
            return method(self, *args, **kwargs)
        except sqlite3.OperationalError as exc:
            if "full" not in str(exc).lower() or not self.release_reserve():
                raise
            return method(self, *args, **kwargs)

    return wrapper  # type: ignore[return-value]


class Database:
    """Connections to one SQLite job database.

    Parameters
    ----------
    path : Path
        The database file (created with its schema, or migrated, if needed).
    create : bool
        Create or migrate the schema and switch to WAL (worker processes open an existing store).
    """

    def __init__(self, path: Path, *, create: bool = True) -> None:
        self.path = Path(path)
        self._local = threading.local()
        self._lock = threading.Lock()
        self._all: builtins.list[sqlite3.Connection] = []
        self.migrated_v0 = False
        if create:
            self._create()

    def _create(self) -> None:
        check_file(self.path)
        try:
            self._create_schema()
        except sqlite3.OperationalError as exc:  # a read-only file system: reads only
            if self._conn() is getattr(self._local, "conn", None):
                raise
            log.warning("job store opened read-only: %s", exc)

    def _create_schema(self) -> None:
        conn = self._conn()
        if conn.execute("PRAGMA journal_mode").fetchone()[0] != "wal":
            conn.execute("PRAGMA journal_mode=WAL")
        if conn.execute("PRAGMA user_version").fetchone()[0] == _SCHEMA_VERSION:
            return  # nothing to write (a full disk must not keep the store from opening)
        with self._write() as conn:
            version = conn.execute("PRAGMA user_version").fetchone()[0]
            columns = {r[1] for r in conn.execute("PRAGMA table_info(jobs)")}
            if version == 0 and "report" in columns:
                self._migrate_v0(conn)
            for statement in _SCHEMA.split(";"):
                if statement.strip():
                    conn.execute(statement)
            conn.execute(f"PRAGMA user_version = {_SCHEMA_VERSION}")

    def _migrate_v0(self, conn: sqlite3.Connection) -> None:
        for column in _V0_ADDED:
            conn.execute(f"ALTER TABLE jobs ADD COLUMN {column}")
        conn.execute(_V0_PROGRESS)
        for column in _V0_DROPPED:
            conn.execute(f"ALTER TABLE jobs DROP COLUMN {column}")
        self.migrated_v0 = True

    # -- connections ---------------------------------------------------------------------
    def _conn(self) -> sqlite3.Connection:
        conn: sqlite3.Connection | None = getattr(self._local, "conn", None)
        if conn is None or getattr(self._local, "pid", None) != os.getpid():
            try:
                conn = sqlite3.connect(
                    self.path, timeout=30.0, isolation_level=None, check_same_thread=False
                )
                conn.execute("PRAGMA schema_version").fetchone()
            except sqlite3.OperationalError:
                if not self.path.exists():
                    raise
                return self._read_only()  # not cached: the next call tries read-write again
            conn.row_factory = sqlite3.Row
            conn.execute("PRAGMA synchronous=FULL")
            conn.execute("PRAGMA busy_timeout=30000")
            self._local.conn = conn
            self._local.pid = os.getpid()
            with self._lock:
                self._all.append(conn)
        return conn

    def _read_only(self) -> sqlite3.Connection:
        """A connection for a store on a read-only file system (reads only; SQLite cannot open
        a WAL database there otherwise). ``immutable``: nothing can change the file meanwhile."""
        conn = sqlite3.connect(f"{self.path.as_uri()}?mode=ro&immutable=1", uri=True,
                               isolation_level=None, check_same_thread=False)  # fmt: skip
        conn.row_factory = sqlite3.Row
        return conn

    @contextmanager
    def _write(self) -> Iterator[sqlite3.Connection]:
        """A write transaction that takes the database lock up front (no upgrade deadlocks)."""
        conn = self._conn()
        conn.execute("BEGIN IMMEDIATE")
        try:
            yield conn
        except BaseException:
            with contextlib.suppress(sqlite3.Error):  # a failed COMMIT may have rolled back
                conn.execute("ROLLBACK")
            raise
        try:
            conn.execute("COMMIT")
        except BaseException:
            with contextlib.suppress(sqlite3.Error):
                conn.execute("ROLLBACK")
            raise

    @property
    def reserve(self) -> Path:
        """The reserve file (released to record outcomes on a full disk)."""
        return self.path.with_name(RESERVE_NAME)

    def release_reserve(self) -> bool:
        """Delete the reserve file; whether there was one."""
        try:
            self.reserve.unlink()
        except FileNotFoundError:
            return False
        return True

    def keep_reserve(self, size: int, min_free: int = 0) -> bool:
        """(Re)create the reserve of ``size`` bytes when the disk has room for it and
        ``min_free`` more; whether it exists afterwards."""
        if size <= 0:
            return False
        if self.reserve.exists() and self.reserve.stat().st_size >= size:
            return True
        st = os.statvfs(self.path.parent)
        if st.f_bavail * st.f_frsize < size + min_free:
            return False
        tmp = self.reserve.with_suffix(".tmp")
        try:
            with open(tmp, "wb") as fh:
                fh.truncate(0)
                for _ in range(0, size, 1 << 20):
                    fh.write(b"\0" * min(1 << 20, size - fh.tell()))
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, self.reserve)
        except OSError:
            tmp.unlink(missing_ok=True)
            return False
        return True

    def close(self) -> None:
        """Close every connection this object opened in this process."""
        with self._lock:
            conns, self._all = self._all, []
        for conn in conns:
            with contextlib.suppress(sqlite3.Error):  # closing is best effort
                conn.close()
        self._local = threading.local()

