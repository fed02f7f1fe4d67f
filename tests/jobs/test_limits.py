"""Bounded resources and retries of the embedded queue: the memory cap, OOM kills, crash bursts,
stray temporary files, and errors that carry no server paths."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from service.jobs import JobSize, JobStatus, LocalQueue, problems
from service.jobs.limits import limit_memory
from service.jobs.queue import NewJob
from tests.jobs.jobs_fakes import script
from tests.jobs.jobs_helpers import PARAMS, pid_gone, start_server, wait_finished, wait_for

MakeQueue = Callable[..., LocalQueue]
MIB = 1024 * 1024


def test_a_job_above_the_memory_cap_fails_alone(make_queue: MakeQueue) -> None:
    queue = make_queue(memory_limit=200 * MIB)
    tiny = JobSize(n=3, dim=2, kind="cloud")  # what the estimate sees: the script lies about it
    hog = queue.submit(NewJob.check(script("hog", bytes=2048 * MIB), "json", PARAMS, size=tiny))
    fine = queue.submit(NewJob.check(script("hog", bytes=20 * MIB), "json", PARAMS, size=tiny))
    done = wait_finished(queue, hog.id, timeout=30)
    assert done.status is JobStatus.FAILED and done.attempts == 1
    assert done.problem is not None and done.problem["code"] == "out-of-memory"
    assert wait_finished(queue, fine.id, timeout=30).status is JobStatus.SUCCEEDED


def test_limit_memory_caps_the_address_space_of_the_process() -> None:
    code = (
        "import sys, resource, numpy as np\n"
        "from service.jobs.limits import limit_memory\n"
        "cap = limit_memory(100 * 1024 * 1024)\n"
        "assert resource.getrlimit(resource.RLIMIT_AS)[0] == cap\n"
        "np.ones(10 * 1024 * 1024)\n"  # 80 MB: fits
        "try:\n    np.ones(50 * 1024 * 1024)\n"  # 400 MB: refused
        "except MemoryError:\n    sys.exit(7)\n"
    )
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    assert subprocess.run([sys.executable, "-c", code], env=env).returncode == 7
    assert limit_memory(None) is None


def test_a_worker_killed_by_sigkill_is_retried_like_a_server_death(make_queue: MakeQueue) -> None:
    queue = make_queue(max_attempts=2)
    once = queue.submit(NewJob.check(script("oom_once"), "json", PARAMS))
    done = wait_finished(queue, once.id, timeout=20)
    assert done.status is JobStatus.SUCCEEDED and done.attempts == 2
    # killed every time
    always = queue.submit(NewJob.check(script("sleep", seconds=30), "json", PARAMS))
    for attempt in (1, 2):

        def run(attempt: int = attempt) -> int | None:
            r = queue.get(always.id)
            ok = r is not None and r.status is JobStatus.RUNNING and r.attempts == attempt
            return r.pid if ok and r is not None else None

        pid = wait_for(run, timeout=20)
        os.kill(pid, signal.SIGKILL)
        wait_for(lambda pid=pid: pid_gone(pid), timeout=5)
    failed = wait_finished(queue, always.id, timeout=20)
    assert failed.status is JobStatus.FAILED and failed.attempts == 2
    assert failed.problem is not None and failed.problem["code"] == "attempts-exhausted"
    assert "SIGKILL" in failed.problem["detail"]


def test_a_burst_of_server_crashes_does_not_exhaust_the_head_of_the_queue(
    make_queue: MakeQueue, tmp_path: Path
) -> None:
    data_dir = tmp_path / "data"
    client = make_queue(start=False, data_dir=data_dir, max_attempts=3)
    ids = [client.submit(NewJob.check(script("sleep", seconds=1.5, steps=3), "json", PARAMS)).id
           for _ in range(4)]  # fmt: skip
    interrupted = 0
    # The backoff must outlast a restart, which takes longer on a busy machine: it is set from
    # the first start's duration (measured, not assumed), so the burst is "within the backoff"
    # at any load.
    backoff = 2.0
    for _ in range(3):  # three crashes in a row, each while jobs run
        started = time.monotonic()
        server = start_server(data_dir, workers=2, retry_backoff=backoff)
        try:
            wait_for(lambda: (data_dir / "server.ready").exists(), timeout=120)
            backoff = max(backoff, 4.0 * (time.monotonic() - started))
            running = wait_for(  # state, not time: some job runs when the crash comes
                lambda: [j for j in ids if client.get(j).status is JobStatus.RUNNING],  # type: ignore[union-attr]
                timeout=120,
            )
            interrupted += len(running)
        finally:
            server.send_signal(signal.SIGKILL)
            server.wait(10)
            (data_dir / "server.ready").unlink(missing_ok=True)
    assert interrupted >= 2  # the crashes did hit running jobs
    queue = make_queue(data_dir=data_dir, max_attempts=3, retry_backoff=backoff)
    done = [wait_finished(queue, j, timeout=120 + 4 * backoff) for j in ids]
    assert all(r.status is JobStatus.SUCCEEDED for r in done), [r.problem for r in done]
    assert all(r.attempts <= 3 for r in done)


def test_stray_temporary_files_are_removed(make_queue: MakeQueue) -> None:
    queue = make_queue(start=False, sweep_interval=0.1)
    rec = queue.submit(NewJob.check(script("ok"), "json", PARAMS))
    stray = queue.files.dir(rec.id) / ".result.npy.12345.tmp"
    stray.write_bytes(b"half a file")
    old = time.time() - 3600
    os.utime(stray, (old, old))
    fresh = queue.files.dir(rec.id) / ".report.json.999.tmp"  # a write in flight: kept
    fresh.write_bytes(b"x")
    queue.start()
    wait_for(lambda: not stray.exists(), timeout=5)
    assert fresh.exists()


def test_job_problems_carry_no_server_paths(tmp_path: Path) -> None:
    missing = tmp_path / "secret" / "dir" / "input.ply"
    try:
        missing.read_bytes()
    except OSError as exc:
        problem = problems.from_exception(exc)
    assert str(tmp_path) not in problem["detail"] and "secret" not in problem["detail"]
    assert problem["detail"] == "FileNotFoundError: No such file or directory"
    other = problems.from_exception(RuntimeError(f"cannot parse {missing} at line 3"))
    assert str(tmp_path) not in other["detail"] and "<path>" in other["detail"]
    assert other["detail"].endswith("at line 3")


def test_a_job_estimated_above_the_limit_is_refused_at_submit(make_queue: MakeQueue) -> None:
    from service.core.linalg.resources import estimate_resources
    from service.jobs.errors import JobTooLarge

    queue = make_queue(start=False, memory_limit=256 * MIB)
    big = JobSize(n=5_000_000, dim=3, kind="cloud")
    with pytest.raises(JobTooLarge) as err:
        queue.submit(NewJob.check(script("ok"), "json", PARAMS, size=big))
    problem = err.value.to_dict()
    est = estimate_resources(big.n, big.dim, big.kind, PARAMS, memory_limit=256 * MIB)
    assert problem["estimate_bytes"] == est.memory_bytes > problem["limit_bytes"] == 256 * MIB
    assert err.value.status == 422 and "0.25 GiB" in err.value.message
    assert queue.list()[1] == 0  # nothing stored
    size = JobSize(n=1000, dim=3, kind="cloud")
    small = queue.submit(NewJob.check(script("ok"), "json", PARAMS, size=size))
    assert small.status is JobStatus.QUEUED
