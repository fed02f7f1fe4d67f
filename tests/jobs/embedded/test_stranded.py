"""Issue 34 item 3: no job stranded. A run that cannot record its progress or outcome (a full
disk on a real tmpfs) ends requeued or failed within a bounded time and succeeds once space is
back; a run of this very server that no slot holds any more is found by the sweep."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

from service.jobs import JobStatus, LocalQueue
from service.jobs.queue import NewJob
from tests.jobs.embedded.test_disk import _fill, small_fs  # noqa: F401 (fixture)
from tests.jobs.jobs_fakes import script
from tests.jobs.jobs_helpers import PARAMS, wait_finished, wait_for

MakeQueue = Callable[..., LocalQueue]


def _status(queue: LocalQueue, job_id: str) -> JobStatus:
    rec = queue.get(job_id)
    assert rec is not None
    return rec.status


def test_a_full_disk_mid_run_never_strands_the_job(
    make_queue: MakeQueue,
    small_fs: Path,  # noqa: F811
) -> None:
    """No reserve: the disk fills while the job reports progress and writes its output; the
    record leaves ``running`` (requeued) and the job succeeds once space is back."""
    data_dir = small_fs / "data"
    queue = make_queue(data_dir=data_dir, reserve_bytes=0, min_free_bytes=0, sweep_interval=0.2,
                       workers=1, lease=2.0)  # fmt: skip
    job = queue.submit(
        NewJob.check(script("sleep", seconds=3.0, steps=30, extra_bytes=1 << 20), "json", PARAMS)
    )
    wait_for(lambda: _status(queue, job.id) is JobStatus.RUNNING, timeout=30)
    filler = _fill(small_fs)
    full_at = time.monotonic()
    time.sleep(8.0)  # the disk stays full past the run's end
    filler.unlink()  # space comes back
    freed_at = time.monotonic()
    left = wait_for(lambda: _status(queue, job.id) is not JobStatus.RUNNING, timeout=60)
    assert left
    assert time.monotonic() - full_at < 60 + (freed_at - full_at)
    done = wait_finished(queue, job.id, timeout=120)
    assert done.status is JobStatus.SUCCEEDED, done.problem


def test_the_sweep_requeues_a_run_no_slot_holds(make_queue: MakeQueue) -> None:
    """A run of this server whose slot is gone (it claimed the job, then could not record
    anything): once its lease expired the sweep puts the job back; it then succeeds."""
    queue = make_queue(workers=1, sweep_interval=0.2, lease=1.0)
    busy = queue.submit(NewJob.check(script("sleep", seconds=2.0), "json", PARAMS))
    wait_for(lambda: _status(queue, busy.id) is JobStatus.RUNNING, timeout=30)
    stranded = queue.submit(NewJob.check(script("ok"), "json", PARAMS))
    claim = queue.store.claim(queue.owner, 1.0)  # a slot that claimed it, then vanished
    assert claim is not None and claim.job_id == stranded.id
    assert _status(queue, stranded.id) is JobStatus.RUNNING
    done = wait_finished(queue, stranded.id, timeout=60)
    assert done.status is JobStatus.SUCCEEDED, done.problem
    assert done.attempts == 2  # the stranded run counted as a try


def test_orphan_job_directories_are_swept_while_running(make_queue: MakeQueue) -> None:
    """A job directory whose record is gone (not only at start): removed by the periodic sweep
    once older than ORPHAN_AGE; a young one (a submit in progress) is kept."""
    import os

    from service.jobs.embedded.maintenance import ORPHAN_AGE

    queue = make_queue(sweep_interval=0.2)
    root = queue.files.root
    old, young = root / ("a" * 32), root / ("b" * 32)
    for d in (old, young):
        d.mkdir()
        (d / "input.json").write_text("{}")
    past = time.time() - ORPHAN_AGE - 60
    os.utime(old, (past, past))
    queue._last_strays = 0.0  # the next sweep walks the store (every ORPHAN_AGE otherwise)
    wait_for(lambda: not old.exists(), timeout=30)
    assert young.exists()
