"""A full, then read-only, then corrupted job store on a real (tmpfs) file system."""

from __future__ import annotations

import os
import subprocess
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from service.jobs import JobStatus, LocalQueue
from service.jobs.errors import StorageFull, StorageUnavailable, StoreDamaged
from service.jobs.queue import NewJob
from tests.jobs.jobs_fakes import script
from tests.jobs.jobs_helpers import PARAMS, wait_finished, wait_for

MakeQueue = Callable[..., LocalQueue]
SIZE = 4 * 1024 * 1024


@pytest.fixture
def small_fs(tmp_path: Path) -> Iterator[Path]:
    """A 4 MiB tmpfs mounted for the test (root only), unmounted after."""
    mnt = tmp_path / "fs"
    mnt.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={SIZE}", "tmpfs", str(mnt)],
                          capture_output=True)  # fmt: skip
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.decode().strip()}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


def _fill(directory: Path) -> Path:
    """Write a file until the file system is full; its path."""
    filler = directory / "filler"
    with open(filler, "wb", buffering=0) as fh:
        for chunk in (65536, 4096, 512, 1):  # down to the last byte
            try:
                while True:
                    fh.write(b"\0" * chunk)
            except OSError:
                pass
    return filler


def test_full_disk_fails_running_jobs_refuses_submits_and_recovers(
    make_queue: MakeQueue, small_fs: Path
) -> None:
    data_dir = small_fs / "data"
    opts = {"data_dir": data_dir, "min_free_bytes": 256 * 1024, "reserve_bytes": 128 * 1024,
            "sweep_interval": 0.2}  # fmt: skip
    queue = make_queue(**opts)
    assert (data_dir / "jobs.reserve").stat().st_size == 128 * 1024
    done_before = queue.submit(NewJob.check(script("ok"), "json", PARAMS))
    assert wait_finished(queue, done_before.id).status is JobStatus.SUCCEEDED
    slow = script("sleep", seconds=2.0, steps=4, extra_bytes=1 << 20)
    running = queue.submit(NewJob.check(slow, "json", PARAMS))
    wait_for(lambda: (r := queue.get(running.id)) and r.status is JobStatus.RUNNING)
    filler = _fill(small_fs)

    with pytest.raises(StorageFull) as err:  # 507 at submit
        queue.submit(NewJob.check(script("ok"), "json", PARAMS))
    assert err.value.status == 507 and str(small_fs) not in err.value.message
    health = queue.health()
    assert not health.ok and health.checks["storage"] == "full"

    # not failed, not stuck in "running": back in the queue until space returns
    waiting = wait_for(
        lambda: (r := queue.get(running.id)) and r.status is JobStatus.QUEUED and r, timeout=20
    )
    assert waiting.attempts == 0 and waiting.problem is None

    queue.stop()  # a restart with the disk still full: starts, answers reads
    again = make_queue(**opts)
    assert again.get(done_before.id).status is JobStatus.SUCCEEDED  # type: ignore[union-attr]
    assert again.get(done_before.id).report is not None  # type: ignore[union-attr]
    assert again.list()[1] == 2 and not again.health().ok

    filler.unlink()  # space comes back: the queue recovers by itself
    wait_for(lambda: again.health().ok, timeout=5)
    after = again.submit(NewJob.check(script("ok"), "json", PARAMS))
    assert wait_finished(again, after.id).status is JobStatus.SUCCEEDED
    retried = wait_finished(again, running.id, timeout=60)  # the storage-full run, retried
    assert retried.status is JobStatus.SUCCEEDED, retried.problem
    wait_for(lambda: (data_dir / "jobs.reserve").exists(), timeout=5)  # reserve kept again


def test_read_only_store_is_unavailable_then_recovers(
    make_queue: MakeQueue, small_fs: Path
) -> None:
    # a 4 MiB store: no free-space floor (the default, 64 MiB, is the whole disk here)
    first_queue = make_queue(data_dir=small_fs / "data", reserve_bytes=0, min_free_bytes=0)
    first = first_queue.submit(NewJob.check(script("ok"), "json", PARAMS))
    assert wait_finished(first_queue, first.id).status is JobStatus.SUCCEEDED
    first_queue.stop()  # (a remount needs no file open for writing)
    subprocess.run(["mount", "-o", "remount,ro", str(small_fs)], check=True)
    try:
        queue = make_queue(data_dir=small_fs / "data", reserve_bytes=0, min_free_bytes=0)
        with pytest.raises(StorageUnavailable) as err:
            queue.submit(NewJob.check(script("ok"), "json", PARAMS))
        assert err.value.status == 503
        assert queue.health().checks["storage"] == "read-only"
        assert queue.get(first.id).status is JobStatus.SUCCEEDED  # type: ignore[union-attr]
    finally:
        subprocess.run(["mount", "-o", "remount,rw", str(small_fs)], check=True)
    assert queue.health().ok
    again = queue.submit(NewJob.check(script("ok"), "json", PARAMS))
    assert wait_finished(queue, again.id).status is JobStatus.SUCCEEDED


def test_corrupted_database_is_reported_not_ready(make_queue: MakeQueue, tmp_path: Path) -> None:
    data_dir = tmp_path / "data"
    queue = make_queue(data_dir=data_dir)
    ids = [queue.submit(NewJob.check(script("ok"), "json", PARAMS)).id for _ in range(30)]
    for job_id in ids:
        wait_finished(queue, job_id)
    assert queue.health().checks["database"] == "ok"
    queue.stop()
    running = make_queue(data_dir=data_dir)  # damaged while a server runs on it:
    db = data_dir / "jobs.sqlite3"
    size = db.stat().st_size
    assert size >= 3 * 4096
    with open(db, "r+b") as fh:  # garbage over the pages after the schema page
        fh.seek(4096)
        fh.write(os.urandom(size - 4096))
    health = running.health()  # ... it says so
    assert not health.ok and health.checks["database"] == "corrupt"
    assert "database corrupt" in (health.detail or "")
    with pytest.raises(StoreDamaged, match="malformed"):  # a new one does not start on it
        make_queue(data_dir=data_dir)  # (issue 42; it started before, maintenance failing)
