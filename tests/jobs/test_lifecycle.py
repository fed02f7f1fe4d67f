"""LocalQueue life cycle with a scripted fake job function (no solver involved)."""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from service.jobs import JobQueue, JobStatus, LocalQueue
from service.jobs.queue import NewJob
from tests.jobs.jobs_fakes import script
from tests.jobs.jobs_helpers import PARAMS, pid_gone, wait_finished, wait_for

MakeQueue = Callable[..., LocalQueue]


def runs_of(queue: LocalQueue, job_id: str) -> list[int]:
    """Pids of the worker processes that ran the job (written by the fake)."""
    path = queue.files.dir(job_id) / "pids"
    return [int(x) for x in path.read_text().split()] if path.exists() else []


def running_pid(queue: LocalQueue, job_id: str) -> int:
    """Wait until the job runs in a process that started the fake; its pid."""

    def ready() -> int | None:
        rec = queue.get(job_id)
        pids = runs_of(queue, job_id)
        return rec.pid if rec and rec.status is JobStatus.RUNNING and rec.pid and pids else None

    return wait_for(ready)  # type: ignore[no-any-return]


def test_local_queue_implements_the_protocol(make_queue: MakeQueue) -> None:
    assert isinstance(make_queue(start=False), JobQueue)


def test_submit_runs_to_success_with_report_and_result_on_disk(make_queue: MakeQueue) -> None:
    queue = make_queue()
    rec = queue.submit(NewJob.check(script("ok", steps=3), "json", PARAMS, filename="in.json"))
    assert rec.status is JobStatus.QUEUED and rec.attempts == 0
    assert queue.files.input(rec.id, "json").read_bytes() == script("ok", steps=3)

    done = wait_finished(queue, rec.id)
    assert done.status is JobStatus.SUCCEEDED
    assert done.attempts == 1 and done.problem is None
    assert done.report is not None and done.report["iterations"] == 3
    on_disk = json.loads(queue.files.report(rec.id).read_text())
    assert on_disk == done.report
    points = np.load(queue.files.result_points(rec.id))
    assert points.shape == (3, 2)
    assert done.phi == pytest.approx(done.report["phi"])
    assert done.run_seconds is not None and done.run_seconds > 0
    assert done.expires_at == pytest.approx(done.finished_at + 3600.0)

    as_dict = done.to_dict()
    json.dumps(as_dict)  # JSON-ready
    assert as_dict["status"] == "succeeded" and as_dict["filename"] == "in.json"
    assert as_dict["params"] == {**PARAMS.model_dump(mode="json", exclude_none=True)}
    assert "pid" not in as_dict

    stats = wait_for(lambda: (s := queue.stats())["finished_total"]["succeeded"] and s, 3)
    assert stats["counts"]["succeeded"] == 1 and stats["queue_depth"] == 0
    assert stats["finished_total"]["succeeded"] == 1
    assert stats["duration_count"] == 1 and len(stats["durations"]) == 1
    assert stats["duration_buckets"][-1] == [float("inf"), 1]


def test_progress_is_visible_while_running(make_queue: MakeQueue) -> None:
    queue = make_queue()
    rec = queue.submit(NewJob.check(script("sleep", seconds=1.5, steps=10), "json", PARAMS))
    seen: list[tuple[JobStatus, int | None, float | None]] = []
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline:
        cur = queue.get(rec.id)
        assert cur is not None
        seen.append((cur.status, cur.iteration, cur.relative_error))
        if cur.finished:
            break
        time.sleep(0.03)
    midway = [it for status, it, _ in seen if status is JobStatus.RUNNING and it]
    assert any(1 <= it < 10 for it in midway)  # seen mid-way, not just at the end
    assert midway == sorted(midway)
    assert all(rel is not None and rel > 0 for status, it, rel in seen if it)
    final = queue.get(rec.id)
    assert final is not None and final.status is JobStatus.SUCCEEDED and final.iteration == 10


def test_cancel_queued_job_never_runs(make_queue: MakeQueue) -> None:
    queue = make_queue(workers=1)
    blocker = queue.submit(NewJob.check(script("sleep", seconds=20), "json", PARAMS))
    waiting = queue.submit(NewJob.check(script("ok"), "json", PARAMS))
    running_pid(queue, blocker.id)
    cancelled = queue.cancel(waiting.id)
    assert cancelled is not None and cancelled.status is JobStatus.CANCELLED
    assert queue.cancel(blocker.id).status is JobStatus.CANCELLED  # type: ignore[union-attr]
    time.sleep(0.5)  # the slot is free again: the cancelled job must still not run
    assert runs_of(queue, waiting.id) == []
    assert queue.get(waiting.id).status is JobStatus.CANCELLED  # type: ignore[union-attr]
    assert queue.get(waiting.id).attempts == 0  # type: ignore[union-attr]


def test_cancel_running_job_kills_its_process(make_queue: MakeQueue) -> None:
    queue = make_queue()
    rec = queue.submit(NewJob.check(script("sleep", seconds=30), "json", PARAMS))
    pid = running_pid(queue, rec.id)
    assert not pid_gone(pid)
    t0 = time.monotonic()
    cancelled = queue.cancel(rec.id)
    assert time.monotonic() - t0 < 15.0  # SIGTERM, not the 30 s of the job (any load)
    assert cancelled is not None and cancelled.status is JobStatus.CANCELLED
    wait_for(lambda: pid_gone(pid), timeout=3.0)
    assert not queue.files.report(rec.id).exists()
    time.sleep(0.3)
    assert queue.get(rec.id).status is JobStatus.CANCELLED  # type: ignore[union-attr]
    assert queue.stats()["busy_workers"] == 0
    # cancelling again, or a finished job, changes nothing
    assert queue.cancel(rec.id).status is JobStatus.CANCELLED  # type: ignore[union-attr]
    assert queue.cancel("0" * 32) is None


def test_crashing_jobs_fail_alone(make_queue: MakeQueue) -> None:
    queue = make_queue(workers=2)
    scripts = {
        "exit": script("exit", code=3),
        "segfault": script("segfault"),
        "raise": script("raise"),
        "core_error": script("core_error"),
    }
    bad = {
        name: queue.submit(NewJob.check(data, "json", PARAMS)).id for name, data in scripts.items()
    }
    good = [queue.submit(NewJob.check(script("ok"), "json", PARAMS)).id for _ in range(3)]
    results = {name: wait_finished(queue, job_id) for name, job_id in bad.items()}
    assert all(r.status is JobStatus.FAILED for r in results.values())
    assert all(wait_finished(queue, j).status is JobStatus.SUCCEEDED for j in good)

    exited = results["exit"].problem
    assert exited["code"] == "worker-crashed" and "code 3" in exited["detail"]  # type: ignore[index]
    segv = results["segfault"].problem
    assert segv["code"] == "worker-crashed" and "SIGSEGV" in segv["detail"]  # type: ignore[index]
    raised = results["raise"].problem
    assert raised == {  # one line, no traceback
        "code": "internal-error",
        "title": "Internal error",
        "detail": "RuntimeError: boom second line of a long story",
    }
    typed = results["core_error"].problem
    assert typed["code"] == "tau-out-of-range" and typed["field"] == "params.tau"  # type: ignore[index]
    assert typed["valid_range"] == [0.0, 2.0]  # type: ignore[index]
    assert all(r.attempts == 1 for r in results.values())  # crashes are not retried
    expected = {"succeeded": 3, "failed": 4, "cancelled": 0}  # counted as the slots settle
    wait_for(lambda: queue.stats()["finished_total"] == expected, timeout=3)


def test_timeout_kills_the_job_and_the_queue_goes_on(make_queue: MakeQueue) -> None:
    queue = make_queue(workers=1, job_timeout=1.0)
    slow = queue.submit(NewJob.check(script("sleep", seconds=30), "json", PARAMS))
    after = queue.submit(NewJob.check(script("ok"), "json", PARAMS))
    pid = running_pid(queue, slow.id)
    rec = wait_finished(queue, slow.id, timeout=8)
    assert rec.status is JobStatus.FAILED
    assert rec.problem is not None and rec.problem["code"] == "timeout"
    ran = rec.finished_at - rec.started_at  # type: ignore[operator]
    assert 1.0 <= ran < 6.0  # killed at the limit, long before the job's 30 s
    assert pid_gone(pid)
    assert wait_finished(queue, after.id).status is JobStatus.SUCCEEDED


def test_stop_requeues_running_jobs_without_counting_a_try(make_queue: MakeQueue) -> None:
    queue = make_queue(workers=1)
    rec = queue.submit(NewJob.check(script("sleep", seconds=30), "json", PARAMS))
    pid = running_pid(queue, rec.id)
    queue.stop()
    assert pid_gone(pid)
    stopped = queue.get(rec.id)
    assert stopped is not None and stopped.status is JobStatus.QUEUED and stopped.attempts == 0
    # the job runs again on the next start (short this time: rewrite its script)
    queue.files.input(rec.id, "json").write_bytes(script("ok"))
    again = make_queue(data_dir=queue.data_dir)
    done = wait_finished(again, rec.id)
    assert done.status is JobStatus.SUCCEEDED and done.attempts == 1
    assert len(runs_of(again, rec.id)) == 2


def test_delete_only_finished_jobs(make_queue: MakeQueue) -> None:
    queue = make_queue(workers=1)
    done = queue.submit(NewJob.check(script("ok"), "json", PARAMS))
    wait_finished(queue, done.id)
    running = queue.submit(NewJob.check(script("sleep", seconds=30), "json", PARAMS))
    running_pid(queue, running.id)
    assert queue.delete(running.id) is False
    assert queue.get(running.id) is not None
    assert queue.delete(done.id) is True
    assert queue.get(done.id) is None and not queue.files.dir(done.id).exists()
    assert queue.result(done.id) is None
    assert queue.delete(done.id) is False
    assert queue.delete("../../etc") is False and queue.get("../x") is None
    queue.cancel(running.id)
    assert queue.delete(running.id) is True


def test_results_expire_after_ttl(make_queue: MakeQueue) -> None:
    queue = make_queue(result_ttl=0.5, sweep_interval=0.1)
    keep = queue.submit(NewJob.check(script("sleep", seconds=30), "json", PARAMS))
    rec = queue.submit(NewJob.check(script("ok"), "json", PARAMS))
    finished = wait_finished(queue, rec.id)
    assert finished.expires_at == pytest.approx(finished.finished_at + 0.5)  # type: ignore[operator]
    wait_for(lambda: queue.get(rec.id) is None, timeout=5)
    wait_for(lambda: not queue.files.dir(rec.id).exists(), timeout=1)  # row first, then files
    running = queue.get(keep.id)
    assert running is not None and running.status is JobStatus.RUNNING  # never expired


def test_concurrent_submissions_all_complete(make_queue: MakeQueue) -> None:
    queue = make_queue(workers=2)
    ids: list[str] = []
    lock = threading.Lock()
    errors: list[BaseException] = []

    def client() -> None:
        try:
            for _ in range(4):
                job_id = queue.submit(NewJob.check(script("ok", steps=1), "json", PARAMS)).id
                with lock:
                    ids.append(job_id)
        except BaseException as exc:  # pragma: no cover - reported below
            errors.append(exc)

    threads = [threading.Thread(target=client) for _ in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors and len(set(ids)) == 24
    assert all(wait_finished(queue, j, 30).status is JobStatus.SUCCEEDED for j in ids)
    assert all(len(runs_of(queue, j)) == 1 for j in ids)  # each ran exactly once
    page, total = queue.list(limit=10, status="succeeded")
    assert total == 24 and len(page) == 10
    assert all(r.report is None for r in page)  # list() leaves reports out
    assert [r.created_at for r in page] == sorted((r.created_at for r in page), reverse=True)
    paged = [r.id for offset in (0, 10, 20) for r in queue.list(offset, 10)[0]]
    assert sorted(paged) == sorted(ids)


def test_submit_validates_format_and_params(make_queue: MakeQueue, tmp_path: Path) -> None:
    queue = make_queue(start=False)
    with pytest.raises(ValueError, match="unknown format"):
        queue.submit(NewJob.check(b"x", "svg", PARAMS))
    with pytest.raises(ValueError):
        queue.submit(NewJob.check(b"x", "json", {"tau": 1.0, "lam": 1.0}))
    rec = queue.submit(NewJob.check(script("ok"), "JSON", {"rms": 0.1}))
    assert rec.fmt == "json" and rec.params["rms"] == 0.1 and "tau" not in rec.params
    assert queue.get(rec.id).status is JobStatus.QUEUED  # type: ignore[union-attr]
    assert list((tmp_path / "data" / "jobs").iterdir()) == [queue.files.dir(rec.id)]
