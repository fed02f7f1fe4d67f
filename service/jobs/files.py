"""File layout of the job store and durable (fsynced, atomic) writes.

::

    data_dir/
      jobs.sqlite3            metadata (see service.jobs.store)
      jobs/<id>/input.<fmt>   the uploaded file, fsynced before submit returns
      jobs/<id>/result.npy    smoothed points, shape (n, s), same order as the input geometry
      jobs/<id>/result.<fmt>  the smoothed document written back in the input's format
      jobs/<id>/report.json   SmoothResult.report()
"""

from __future__ import annotations

import json
import os
import re
import shutil
import time
from pathlib import Path
from typing import Any

__all__ = ["JobFiles", "is_job_id", "write_durable"]

_JOB_ID = re.compile(r"^[0-9a-f]{32}$")
_FMT = re.compile(r"^[a-z0-9]{1,16}$")


def is_job_id(job_id: object) -> bool:
    """Whether ``job_id`` has the shape of a job id (guards every path built from it)."""
    return isinstance(job_id, str) and bool(_JOB_ID.match(job_id))


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def write_durable(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically: temp file, fsync, rename, fsync the directory.

    Parameters
    ----------
    path : Path
        Destination; its directory must exist.
    data : bytes
        Content.
    """
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with open(tmp, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)
    _fsync_dir(path.parent)


class JobFiles:
    """Paths of one data directory's job files.

    Parameters
    ----------
    data_dir : Path
        Root of the job store.
    """

    def __init__(self, data_dir: Path) -> None:
        self.root = Path(data_dir) / "jobs"
        self.root.mkdir(parents=True, exist_ok=True)

    def dir(self, job_id: str) -> Path:
        """Directory of one job (``ValueError`` for anything that is not a job id)."""
        if not is_job_id(job_id):
            raise ValueError(f"not a job id: {job_id!r}")
        return self.root / job_id

    def input(self, job_id: str, fmt: str) -> Path:
        """The stored input file."""
        if not _FMT.match(fmt):
            raise ValueError(f"not a format name: {fmt!r}")
        return self.dir(job_id) / f"input.{fmt}"

    def result_points(self, job_id: str) -> Path:
        """Smoothed points as ``.npy``."""
        return self.dir(job_id) / "result.npy"

    def result_file(self, job_id: str, fmt: str) -> Path:
        """The smoothed document in the input's format."""
        if not _FMT.match(fmt):
            raise ValueError(f"not a format name: {fmt!r}")
        return self.dir(job_id) / f"result.{fmt}"

    def report(self, job_id: str) -> Path:
        """``SmoothResult.report()`` as JSON."""
        return self.dir(job_id) / "report.json"

    def create(
        self, job_id: str, fmt: str, data: bytes, options: dict[str, Any] | None = None
    ) -> Path:
        """Create the job directory and store its input durably; returns the input path.

        ``options`` (how to read the input, e.g. ``{"weld": true}``) go to ``options.json``.
        """
        path = self.input(job_id, fmt)
        path.parent.mkdir()
        _fsync_dir(self.root)
        if options:
            write_durable(path.parent / "options.json", json.dumps(options).encode())
        write_durable(path, data)
        return path

    def read_options(self, job_id: str) -> dict[str, Any]:
        """The job's input options (``{}`` when none were stored)."""
        try:
            return dict(json.loads((self.dir(job_id) / "options.json").read_text()))
        except FileNotFoundError:
            return {}

    def remove(self, job_id: str) -> None:
        """Delete a job's directory (no error if it is gone)."""
        shutil.rmtree(self.dir(job_id), ignore_errors=True)

    def orphans(self, known: set[str], min_age: float) -> list[str]:
        """Job directories without a record, older than ``min_age`` seconds.

        They are left by a crash between writing the input and committing the record (or
        between deleting a record and its files).
        """
        now = time.time()
        out = []
        for entry in self.root.iterdir():
            if is_job_id(entry.name) and entry.name not in known:
                try:
                    age = now - entry.stat().st_mtime
                except FileNotFoundError:
                    continue
                if age >= min_age:
                    out.append(entry.name)
        return out
