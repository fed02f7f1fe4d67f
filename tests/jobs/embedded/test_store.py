"""The pieces under LocalQueue: conditional run writes, crash recovery, files, problems."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from service.core.errors import IndexOutOfRange
from service.core.progress import ProgressEvent
from service.io.errors import FormatError, UnsupportedFormat
from service.jobs import JobStatus, LocalQueue, problems
from service.jobs.admit import JobRow
from service.jobs.embedded.maintenance import owner_dead as _owner_dead
from service.jobs.embedded.store import JobStore
from service.jobs.files import JobFiles, is_job_id, write_durable
from service.jobs.progress import final_progress
from service.jobs.queue import NewJob
from service.jobs.runner import JobContext, RunLost
from tests.jobs.jobs_fakes import script
from tests.jobs.jobs_helpers import PARAMS, pid_gone, wait_for

MakeQueue = Callable[..., LocalQueue]


@pytest.fixture
def store(tmp_path: Path) -> JobStore:
    s = JobStore(tmp_path / "jobs.sqlite3", result_ttl=60.0)
    yield s
    s.close()


def _add(store: JobStore, job_id: str = "a" * 32, max_attempts: int = 3) -> str:
    store.insert(JobRow(job_id, "json", None, {"tau": 1.0}, 10, max_attempts))
    return job_id


def _progress(iteration: int, phi: float = 2.0) -> dict[str, object]:
    return {"stage": "search", "iteration": iteration, "lambda": 0.5, "phi": phi, "tau": 1.0,
            "relative_error": 1.0}  # fmt: skip


def test_store_uses_wal_and_claims_in_fifo_order(store: JobStore) -> None:
    mode = store._conn().execute("PRAGMA journal_mode").fetchone()[0]
    assert mode == "wal"
    first, second = _add(store, "1" * 32), _add(store, "2" * 32)
    a, b = store.claim("me", 5.0), store.claim("me", 5.0)
    assert (a.job_id, a.attempt, b.job_id) == (first, 1, second)  # type: ignore[union-attr]
    assert store.claim("me", 5.0) is None
    rec = store.get(first)
    assert rec is not None and rec.status is JobStatus.RUNNING and rec.attempts == 1


def test_a_run_that_lost_its_job_cannot_write(store: JobStore) -> None:
    job_id = _add(store)
    claim = store.claim("me", 5.0)
    assert claim is not None
    assert store.progress(job_id, "me", 1, _progress(1))
    assert not store.progress(job_id, "someone-else", 1, _progress(2))
    rec, previous = store.cancel(job_id)
    assert previous is JobStatus.RUNNING and rec.status is JobStatus.CANCELLED  # type: ignore[union-attr]
    assert not store.progress(job_id, "me", 1, _progress(3))
    assert not store.succeed(job_id, "me", 1, final_progress({"phi": 1.0}, 0.1), 0.1)
    assert not store.fail(job_id, "me", 1, {"code": "x"})
    assert not store.renew(job_id, "me", 1, 5.0)
    rec = store.get(job_id)
    assert rec.status is JobStatus.CANCELLED and rec.iteration == 1  # type: ignore[union-attr]
    assert store.cancel(job_id)[1] is None  # already finished: unchanged


def test_stale_attempt_cannot_overwrite_a_newer_run(store: JobStore) -> None:
    job_id = _add(store)
    store.claim("old", 5.0)
    assert store.requeue(job_id, "old", 1, count_attempt=True)
    store.claim("new", 5.0)
    assert not store.succeed(job_id, "old", 1, final_progress({"phi": 0.0}, 0.1), 0.1)
    assert store.succeed(job_id, "new", 2, final_progress({"phi": 1.0, "iterations": 4}, 0.1), 0.1)
    rec = store.get(job_id)
    assert rec.status is JobStatus.SUCCEEDED and rec.attempts == 2  # type: ignore[union-attr]
    # the report itself lives in the job's report.json (read by LocalQueue.get); the row keeps
    # the final progress taken from it
    assert rec.phi == 1.0 and rec.iteration == 4  # type: ignore[union-attr]


def test_recovery_requeues_only_runs_of_dead_owners(make_queue: MakeQueue) -> None:
    queue = make_queue(start=False, max_attempts=2)
    ids = [queue.submit(NewJob.check(script("ok"), "json", PARAMS)).id for _ in range(4)]
    store = queue.store
    host = socket.gethostname()
    alive_elsewhere = f"{host}@{os.getppid()}:x"  # a live process on this host, lease valid
    owners = {
        ids[0]: (alive_elsewhere, 60.0),  # untouched
        ids[1]: (f"{host}@{os.getpid()}:gone", 60.0),  # this pid, but no live queue: dead
        ids[2]: ("otherhost@1:x", -1.0),  # lease expired
        ids[3]: (f"{host}@{os.getpid()}:gone2", 60.0),  # dead, out of attempts
    }
    for job_id, (owner, lease) in owners.items():
        claim = store.claim(owner, lease)
        assert claim is not None and claim.job_id == job_id
    store.requeue(ids[3], owners[ids[3]][0], 1, count_attempt=True)
    store.claim(owners[ids[3]][0], 60.0)  # second run of ids[3]

    requeued, failed = queue.recover()
    assert sorted(requeued) == sorted([ids[1], ids[2]]) and failed == [ids[3]]
    states = {j: store.get(j) for j in ids}
    assert states[ids[0]].status is JobStatus.RUNNING  # type: ignore[union-attr]
    assert states[ids[1]].status is JobStatus.QUEUED and states[ids[1]].attempts == 1  # type: ignore[union-attr]
    assert states[ids[3]].problem["code"] == "attempts-exhausted"  # type: ignore[index,union-attr]
    assert not _owner_dead(alive_elsewhere) and _owner_dead(owners[ids[1]][0])
    assert not _owner_dead("otherhost@1:x")  # other hosts: only the lease tells


def test_a_zombie_owner_is_dead() -> None:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    try:
        wait_for(lambda: pid_gone(proc.pid), timeout=10)  # exited, not reaped yet: a zombie
        assert Path(f"/proc/{proc.pid}").exists()
        assert _owner_dead(f"{socket.gethostname()}@{proc.pid}:x")
    finally:
        proc.wait()


def test_cancel_from_another_process_kills_the_job(make_queue: MakeQueue) -> None:
    server = make_queue(poll_interval=0.1)
    other = make_queue(start=False, data_dir=server.data_dir)  # e.g. another API worker
    rec = other.submit(NewJob.check(script("sleep", seconds=30), "json", PARAMS))
    pid = wait_for(lambda: (r := server.get(rec.id)) and r.status is JobStatus.RUNNING and r.pid)
    assert other.cancel(rec.id).status is JobStatus.CANCELLED  # type: ignore[union-attr]
    wait_for(lambda: pid_gone(pid), timeout=5)
    wait_for(lambda: server.stats()["busy_workers"] == 0, timeout=3)


def test_orphan_directories_are_removed_on_start(make_queue: MakeQueue) -> None:
    """Another live process uses the store: only old orphans go (a young one may be its submit
    in flight). Nobody else: every orphan goes (a crash left it)."""
    queue = make_queue(start=False)
    kept = queue.submit(NewJob.check(script("ok"), "json", PARAMS)).id
    orphan = queue.files.root / ("f" * 32)
    orphan.mkdir()
    old = time.time() - 3600
    os.utime(orphan, (old, old))
    young = queue.files.root / ("e" * 32)
    young.mkdir()
    holder = subprocess.Popen(  # a live user of the store (holds its shared lock)
        [sys.executable, "-c", "import sys, time\n"
         "from pathlib import Path\n"
         "from service.jobs.files import sole_user\n"
         f"sole_user(Path({str(queue.files.root)!r})); print('held', flush=True)\n"
         "time.sleep(600)\n"],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
        queue.start()
        assert not orphan.exists() and young.exists() and queue.files.dir(kept).exists()
    finally:
        holder.kill()
        holder.wait(10)
    # (nobody else: tests/api/test_crash_leftovers.py, a server restarted after a SIGKILL)


def test_job_files_refuse_anything_but_job_ids(tmp_path: Path) -> None:
    files = JobFiles(tmp_path)
    assert is_job_id("0123456789abcdef0123456789abcdef")
    for bad in ("..", "../etc", "A" * 32, "a" * 31, "a" * 32 + "/x", 5):
        assert not is_job_id(bad)
    with pytest.raises(ValueError):
        files.dir("../../etc")
    with pytest.raises(ValueError):
        files.input("a" * 32, "../x")
    target = tmp_path / "out.bin"
    write_durable(target, b"abc")
    write_durable(target, b"defg")
    assert target.read_bytes() == b"defg"
    assert [p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp")] == []


def test_problems_keep_typed_errors_and_hide_internals() -> None:
    geo = problems.from_exception(
        IndexOutOfRange("face 3 refers to vertex 9", field="geometry.faces", indices=[3, 4])
    )
    assert geo == {
        "code": "index-out-of-range",
        "title": "Invalid geometry",
        "detail": "face 3 refers to vertex 9",
        "field": "geometry.faces",
        "indices": [3, 4],
    }
    fmt = problems.from_exception(FormatError("line 3: not a number", fmt="obj", line=3))
    assert fmt["code"] == "format-error" and fmt["field"] == "file" and fmt["line"] == 3
    assert problems.from_exception(UnsupportedFormat("gpx"))["code"] == "unsupported-format"
    assert problems.from_exception(MemoryError())["code"] == "out-of-memory"
    long = problems.from_exception(KeyError("x" * 1000))
    assert long["code"] == "internal-error" and len(long["detail"]) < 400
    assert "SIGKILL" in problems.crashed(-9)["detail"]
    json.dumps([geo, fmt, long, problems.timed_out(2.0), problems.attempts_exhausted(3)])


def test_progress_is_throttled_and_stops_a_run_that_lost_its_job(tmp_path: Path) -> None:
    writes: list[tuple[str, int, float | None]] = []
    holds = [True]

    def report(progress: dict[str, object]) -> bool:
        writes.append((progress["stage"], progress["iteration"], progress["relative_error"]))  # type: ignore[arg-type]
        return holds[0]

    ctx = JobContext("a" * 32, tmp_path, tmp_path / "input.json", "json", PARAMS, report, 10.0)
    ev = [ProgressEvent("search", tau=2.0, iteration=i, lam=0.1 * i, phi=p) for i, p in
          ((1, 3.0), (2, 2.5), (3, 2.0))]  # fmt: skip
    ctx.progress(ProgressEvent("neighborhoods"))  # a new stage: written at once
    ctx.progress(ev[0])  # a new stage again
    ctx.progress(ev[1])  # same stage, within the interval: held back
    assert writes == [("neighborhoods", 0, None), ("search", 1, 0.5)]
    ctx.flush_progress()
    assert writes[-1] == ("search", 2, 0.25)
    holds[0] = False
    ctx.flush_progress()  # nothing pending: no write
    assert len(writes) == 3
    with pytest.raises(RunLost):
        ctx._last_write = float("-inf")
        ctx.progress(ev[2])


def test_progress_dict_has_stage_percent_and_eta(tmp_path: Path) -> None:
    seen: list[dict[str, object]] = []
    ctx = JobContext("a" * 32, tmp_path, tmp_path / "in.json", "json", PARAMS,
                     lambda p: seen.append(p) or True, 0.0)  # fmt: skip
    ctx.stage("reading")
    for stage in ("neighborhoods", "laplacian", "analysis"):
        ctx.progress(ProgressEvent(stage, tau=1.0))
    tol = PARAMS.tolerance
    for i, rel in enumerate((1.0, 0.1, tol), start=1):  # geometric convergence to the tolerance
        ctx.progress(ProgressEvent("search", tau=1.0, iteration=i, lam=1.0, phi=1.0 + rel))
    ctx.stage("writing")
    stages = [p["stage"] for p in seen]
    assert stages == ["reading", "neighborhoods", "laplacian", "analysis", "search", "search",
                      "search", "writing"]  # fmt: skip
    percents = [float(p["percent"]) for p in seen]  # type: ignore[arg-type]
    assert percents == sorted(percents) and percents[0] == 0.0 and percents[-1] == 95.0
    search = percents[4:7]  # the search slice 40..90, filled on a log scale of the error
    assert search[0] == 40.0 and search[2] == 90.0
    expected_mid = 40.0 + 50.0 * np.log(1.0 / 0.1) / np.log(1.0 / tol)
    assert search[1] == pytest.approx(expected_mid, abs=0.01)
    assert all(p["tau"] == 1.0 for p in seen[2:7])
    late = seen[-1]
    assert late["iteration"] == 3 and late["lambda"] == 1.0  # the search's, carried over
    assert late["tau"] == 1.0 and [p["iteration"] for p in seen] == [0, 0, 0, 0, 1, 2, 3, 3]
    assert late["eta_seconds"] is not None and late["elapsed_seconds"] is not None
    eta, elapsed = float(late["eta_seconds"]), float(late["elapsed_seconds"])  # type: ignore[arg-type]
    assert eta == pytest.approx(elapsed * 5.0 / 95.0, abs=2e-3)
