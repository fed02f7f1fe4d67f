"""Issue 42 finding 7: a lost, replaced or damaged job database never costs a result.

Before: with the WAL deleted or the database deleted, the server started with every job 404
and deleted every job directory as an orphan, finished results included; a truncated or zeroed
database made ``serve`` die with a traceback and exit 11 ("address cannot be bound").
"""

from __future__ import annotations

import logging
import shutil
import sqlite3
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from service.jobs import LocalQueue
from service.jobs.errors import StoreDamaged
from service.jobs.queue import JobStatus, NewJob
from tests.jobs.jobs_fakes import script
from tests.jobs.jobs_helpers import PARAMS, REPO, wait_finished

MakeQueue = Callable[..., LocalQueue]


def _finished_jobs(make_queue: MakeQueue, data: Path, n: int = 3) -> dict[str, bytes]:
    """``n`` succeeded jobs on ``data``: id -> the bytes of the result file."""
    queue = make_queue(data_dir=data)
    out = {}
    for _ in range(n):
        rec = queue.submit(NewJob.check(script("ok"), "json", PARAMS))
        assert wait_finished(queue, rec.id).status is JobStatus.SUCCEEDED
        out[rec.id] = queue.files.result_points(rec.id).read_bytes()
    return out


def _copy(src: Path, dest: Path, database: bool) -> None:
    shutil.copytree(src / "jobs", dest / "jobs")
    if database:  # the main file only: the WAL, where the records are, is lost
        shutil.copy(src / "jobs.sqlite3", dest / "jobs.sqlite3")


@pytest.mark.parametrize("database", [True, False], ids=["wal-lost", "database-deleted"])
def test_a_lost_database_quarantines_the_job_directories(
    make_queue: MakeQueue, tmp_path: Path, caplog: pytest.LogCaptureFixture, database: bool
) -> None:
    results = _finished_jobs(make_queue, tmp_path / "a")
    _copy(tmp_path / "a", tmp_path / "b", database)
    with caplog.at_level(logging.WARNING, logger="geosmooth.jobs"):
        queue = make_queue(data_dir=tmp_path / "b")
    assert not set(results) & queue.store.ids()  # the records are gone indeed
    for job_id, data in results.items():
        assert not queue.files.dir(job_id).exists()
        kept = queue.files.quarantine_dir / job_id
        assert (kept / "result.npy").read_bytes() == data  # nothing deleted
        assert (kept / "input.json").exists()
    said = [r for r in caplog.records if "quarantine" in r.getMessage()]
    assert len(said) == 1 and said[0].levelno == logging.ERROR  # a new, empty database: loud
    assert f"{len(results)} job director" in said[0].getMessage()
    assert queue.submit(NewJob.check(script("ok"), "json", PARAMS))  # it serves new jobs


def _damage(path: Path, how: str) -> None:
    data = path.read_bytes()
    path.write_bytes(b"\0" * len(data) if how == "zeroed" else data[: len(data) // 2])


@pytest.mark.parametrize("how", ["zeroed", "truncated"])
def test_a_damaged_database_is_refused_and_nothing_is_touched(
    make_queue: MakeQueue, tmp_path: Path, how: str
) -> None:
    results = _finished_jobs(make_queue, tmp_path / "a", n=12)
    _copy(tmp_path / "a", tmp_path / "b", database=False)
    src = tmp_path / "a" / "jobs.sqlite3"
    conn = sqlite3.connect(src)
    conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")  # every record in the main file
    conn.close()
    shutil.copy(src, tmp_path / "b" / "jobs.sqlite3")
    _damage(tmp_path / "b" / "jobs.sqlite3", how)
    with pytest.raises(StoreDamaged, match=r"jobs\.sqlite3 is damaged"):
        make_queue(data_dir=tmp_path / "b")
    for job_id, data in results.items():  # untouched
        assert (tmp_path / "b" / "jobs" / job_id / "result.npy").read_bytes() == data
    done = subprocess.run(
        [sys.executable, "-m", "service.cli", "serve", "--data-dir", str(tmp_path / "b"),
         "--port", "1"],
        cwd=REPO, capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    assert done.returncode == 14, done.stderr[-2000:]
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "jobs.sqlite3 is damaged" in lines[0], done.stderr[-2000:]
    assert {p.name for p in (tmp_path / "b" / "jobs").iterdir() if p.is_dir()} == set(results)
