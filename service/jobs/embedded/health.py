"""Readiness of the embedded job store: free space, writability, database integrity.

The cheap checks (``statvfs``, creating and removing a probe file) run on every call; the
database integrity check (SQLite ``quick_check``, O(database size)) at most every
:data:`DB_CHECK_INTERVAL` seconds.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from service.jobs.files import probe_directory
from service.jobs.queue import QueueHealth

__all__ = ["DB_CHECK_INTERVAL", "StorageProbe"]

DB_CHECK_INTERVAL = 10.0


class StorageProbe:
    """Health of a data directory and its database.

    Parameters
    ----------
    data_dir : Path
        The job store's directory.
    min_free : int
        Bytes below which the store counts as full.
    db_check : callable
        ``() -> "ok" | "corrupt" | "unavailable" | "missing"``.
    dirs : sequence of Path
        Further directories the store writes to (the job directories' root): each must exist
        and take a file, like ``data_dir`` (a data directory removed under a live server was
        "ready" while every submit failed).
    db_file : Path, optional
        The database file: ``"missing"`` when it was removed, checked on every call (an open
        connection still reads the unlinked file; what it writes is lost).
    """

    def __init__(self, data_dir: Path, min_free: int, db_check: Callable[[], str],
                 dirs: Sequence[Path] = (), db_file: Path | None = None) -> None:  # fmt: skip
        self.data_dir = Path(data_dir)
        self.db_file = db_file
        self.dirs = [Path(d) for d in dirs]
        self.min_free = min_free
        self._db_check = db_check
        self._db_state = "ok"
        self._db_checked = float("-inf")
        self._lock = threading.Lock()

    def database(self) -> str:
        """The (cached) result of the database check."""
        with self._lock:
            if time.monotonic() - self._db_checked >= DB_CHECK_INTERVAL:
                self._db_state = self._db_check()
                self._db_checked = time.monotonic()
            return self._db_state

    def health(self) -> QueueHealth:
        """Storage and database checks."""
        states = [probe_directory(d, self.min_free) for d in (self.data_dir, *self.dirs)]
        checks = {"storage": next((s for s in states if s != "ok"), "ok"),
                  "database": "missing" if self.db_file and not self.db_file.exists()
                  else self.database()}  # fmt: skip
        bad = [f"{name} {state}" for name, state in checks.items() if state != "ok"]
        return QueueHealth(not bad, checks, ", ".join(bad) or None)
