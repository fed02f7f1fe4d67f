"""The queue contract: tenancy, idempotency, public_dict == the API's Job, typed errors, and a
data directory of the previous version (schema 0) opening unchanged."""

from __future__ import annotations

import json
import sqlite3
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from service.api.schemas import Job
from service.io.errors import FormatError
from service.jobs import JobQueue, JobStatus, LocalQueue
from service.jobs.errors import (
    IdempotencyConflict,
    JobTooLarge,
    StorageFull,
    StorageUnavailable,
    storage_error,
)
from service.jobs.queue import JobSize, NewJob
from tests.jobs.jobs_fakes import script
from tests.jobs.jobs_helpers import PARAMS, wait_finished

MakeQueue = Callable[..., LocalQueue]

# The schema of the previous release (service/jobs/embedded/store.py before schema versions),
# verbatim.
V0_SCHEMA = """
CREATE TABLE IF NOT EXISTS jobs (
    seq INTEGER PRIMARY KEY AUTOINCREMENT, id TEXT NOT NULL UNIQUE, status TEXT NOT NULL,
    fmt TEXT NOT NULL, filename TEXT, params TEXT NOT NULL, input_bytes INTEGER NOT NULL,
    created_at REAL NOT NULL, updated_at REAL NOT NULL, started_at REAL, finished_at REAL,
    attempts INTEGER NOT NULL DEFAULT 0, max_attempts INTEGER NOT NULL, owner TEXT,
    lease_until REAL, pid INTEGER, iteration INTEGER, lam REAL, phi REAL, tau REAL,
    relative_error REAL, problem TEXT, report TEXT, run_seconds REAL
);
CREATE INDEX IF NOT EXISTS jobs_status ON jobs (status, seq);
"""


def test_tenants_see_only_their_jobs(make_queue: MakeQueue) -> None:
    queue = make_queue(start=False)
    mine = queue.submit(NewJob.check(script("ok"), "json", PARAMS, tenant="a" * 16))
    theirs = queue.submit(NewJob.check(script("ok"), "json", PARAMS, tenant="b" * 16))
    assert queue.get(mine.id, tenant="a" * 16) is not None
    assert queue.get(theirs.id, tenant="a" * 16) is None
    assert queue.get(theirs.id) is not None  # no authentication: every job
    page, total = queue.list(tenant="a" * 16)
    assert total == 1 and [r.id for r in page] == [mine.id]
    assert queue.list()[1] == 2
    assert queue.cancel(theirs.id, tenant="a" * 16) is None
    assert queue.get(theirs.id).status is JobStatus.QUEUED  # type: ignore[union-attr]
    queue.cancel(theirs.id)
    assert queue.delete(theirs.id, tenant="a" * 16) is False
    assert queue.delete(theirs.id, tenant="b" * 16) is True


def test_idempotency_key_returns_the_same_job(make_queue: MakeQueue, tmp_path: Path) -> None:
    queue = make_queue(start=False)
    first = queue.submit(
        NewJob.check(script("ok"), "json", PARAMS, tenant="t", idempotency_key="k1")
    )
    spooled = tmp_path / "spool.json"
    spooled.write_bytes(script("ok"))
    again = queue.submit(NewJob.check(spooled, "json", PARAMS, tenant="t", idempotency_key="k1"))
    assert again.id == first.id and not spooled.exists()  # "moved into the store": consumed
    assert len(queue.list()[0]) == 1
    with pytest.raises(IdempotencyConflict) as err:
        queue.submit(
            NewJob.check(script("ok", steps=2), "json", PARAMS, tenant="t", idempotency_key="k1")
        )
    assert err.value.status == 409 and err.value.to_dict()["field"] == "Idempotency-Key"
    with pytest.raises(IdempotencyConflict):  # same body, other parameters
        queue.submit(
            NewJob.check(script("ok"), "json", {"tau": 2.0}, tenant="t", idempotency_key="k1")
        )
    other = queue.submit(
        NewJob.check(script("ok"), "json", PARAMS, tenant="u", idempotency_key="k1")
    )
    assert other.id != first.id  # keys are per tenant
    assert len(list((queue.data_dir / "jobs").iterdir())) == 2  # no input left behind


def test_spooled_input_is_moved_into_the_store(make_queue: MakeQueue, tmp_path: Path) -> None:
    queue = make_queue()
    spooled = tmp_path / "upload.tmp"
    spooled.write_bytes(script("ok"))
    rec = queue.submit(NewJob.check(spooled, "json", PARAMS, filename="in.json"))
    assert not spooled.exists() and rec.input_bytes == len(script("ok"))
    assert wait_finished(queue, rec.id).status is JobStatus.SUCCEEDED


def test_public_dict_is_the_api_job(make_queue: MakeQueue) -> None:
    queue = make_queue()
    rec = queue.submit(NewJob.check(script("ok", steps=2), "json", PARAMS, weld=True,
                       webhook_url="https://hooks.invalid/x"))  # fmt: skip
    queued = rec.public_dict()
    assert queued["progress"]["stage"] == "queued" and queued["progress"]["percent"] == 0.0
    done = wait_finished(queue, rec.id)
    for record in (rec, done):
        data = record.public_dict()
        json.dumps(data, allow_nan=False)
        assert Job.model_validate(data).model_dump(mode="json", by_alias=True) == data
    data = done.public_dict()
    assert data["weld"] is True and data["webhook_url"] == "https://hooks.invalid/x"
    assert data["created_at"].endswith("Z") and data["progress"] is None
    assert data["report"] == done.report and done.public_dict(with_report=False)["report"] is None
    assert data["links"]["result"] == f"/v1/jobs/{rec.id}/result"


def test_failed_job_public_error_is_problem_details(make_queue: MakeQueue) -> None:
    queue = make_queue()
    done = wait_finished(queue, queue.submit(NewJob.check(script("core_error"), "json", PARAMS)).id)
    error = done.public_dict()["error"]
    assert error["type"] == "urn:geosmooth:problem:tau-out-of-range"
    assert error["title"] == "Invalid parameters" and error["field"] == "params.tau"


def test_typed_errors_carry_their_problem_metadata() -> None:
    err = JobTooLarge("too big", field="file", estimate_bytes=10, limit_bytes=5)
    assert (err.status, err.code, err.title) == (422, "job-too-large", "Job too large")
    assert err.to_dict() == {"code": "job-too-large", "message": "too big", "field": "file",
                             "estimate_bytes": 10, "limit_bytes": 5}  # fmt: skip
    full = storage_error(OSError(28, "No space left on device", "/secret/path"))
    assert isinstance(full, StorageFull) and full.status == 507 and "/secret" not in full.message
    ro = storage_error(OSError(30, "Read-only file system", "/secret/path"))
    assert isinstance(ro, StorageUnavailable) and ro.status == 503
    assert isinstance(storage_error(sqlite3.OperationalError("database or disk is full")),
                      StorageFull)  # fmt: skip
    assert isinstance(storage_error(sqlite3.DatabaseError("file is not a database")),
                      StorageUnavailable)  # fmt: skip
    assert storage_error(sqlite3.IntegrityError("UNIQUE constraint failed")) is None
    assert storage_error(ValueError("x")) is None


def _v0_data_dir(data_dir: Path) -> dict[str, str]:
    """A data directory as the previous release left it: a finished welded job, a queued one."""
    jobs = data_dir / "jobs"
    ids = {"done": "d" * 32, "queued": "e" * 32}
    data_dir.mkdir(parents=True)
    conn = sqlite3.connect(data_dir / "jobs.sqlite3")
    conn.executescript(V0_SCHEMA)
    report = {"phi": 0.5, "tau": 0.5, "lambda": 0.1, "relative_error": 0.0, "iterations": 4}
    t = time.time() - 60
    conn.execute(
        "INSERT INTO jobs (id, status, fmt, params, input_bytes, created_at, updated_at,"
        " started_at, finished_at, attempts, max_attempts, iteration, lam, phi, tau,"
        " relative_error, report, run_seconds) VALUES (?, 'succeeded', 'json', ?, 10, ?, ?,"
        " ?, ?, 1, 3, 4, 0.1, 0.5, 0.5, 0.0, ?, 0.25)",
        (ids["done"], json.dumps({"tau": 0.5}), t, t + 2, t + 1, t + 2, json.dumps(report)),
    )
    conn.execute(
        "INSERT INTO jobs (id, status, fmt, params, input_bytes, created_at, updated_at,"
        " max_attempts) VALUES (?, 'queued', 'json', ?, 10, ?, ?, 3)",
        (ids["queued"], json.dumps({"tau": 1.0}), t + 3, t + 3),
    )
    conn.commit()
    conn.close()
    for job_id in ids.values():
        (jobs / job_id).mkdir(parents=True)
        (jobs / job_id / "input.json").write_bytes(script("ok"))
    (jobs / ids["done"] / "options.json").write_text('{"weld": true}')
    (jobs / ids["done"] / "report.json").write_text(json.dumps(report))
    return ids


def test_a_version_0_data_dir_opens_and_runs(make_queue: MakeQueue, tmp_path: Path) -> None:
    data_dir = tmp_path / "old"
    ids = _v0_data_dir(data_dir)
    queue = make_queue(data_dir=data_dir)
    done = queue.get(ids["done"])
    assert done is not None and done.status is JobStatus.SUCCEEDED
    assert done.weld is True and not (data_dir / "jobs" / ids["done"] / "options.json").exists()
    assert done.report is not None and done.report["iterations"] == 4
    assert (done.iteration, done.lam, done.phi, done.run_seconds) == (4, 0.1, 0.5, 0.25)
    assert wait_finished(queue, ids["queued"]).status is JobStatus.SUCCEEDED
    columns = {r[1] for r in sqlite3.connect(data_dir / "jobs.sqlite3").execute(
        "PRAGMA table_info(jobs)")}  # fmt: skip
    assert "report" not in columns and {"weld", "tenant", "progress"} <= columns
    queue.stop()
    again = make_queue(data_dir=data_dir)  # opening a migrated store changes nothing
    assert again.get(ids["done"]) == done


def test_the_protocol_is_complete(make_queue: MakeQueue) -> None:
    queue = make_queue(start=False)
    assert isinstance(queue, JobQueue)
    for name in ("result_file", "result_url", "health"):
        assert name in JobQueue.__dict__
    assert queue.result_url("0" * 32, "ply") is None


def test_both_backends_take_one_submit_signature() -> None:
    """``submit(job: NewJob)``: one parameter, written the same in the protocol and both
    backends (it was nine parameters written three times)."""
    import inspect

    from service.jobs.distributed.queue import RQQueue

    signatures = {str(inspect.signature(f)) for f in (JobQueue.submit, LocalQueue.submit,
                                                      RQQueue.submit)}  # fmt: skip
    assert signatures == {"(self, job: 'NewJob') -> 'JobRecord'"}


def test_a_checked_job_is_stored_without_reading_its_input_again(make_queue: MakeQueue) -> None:
    """The intake's ``size`` feeds the memory estimate: the queue does not parse the input (here
    bytes no reader accepts); without ``size`` it reads it and refuses them."""
    queue = make_queue(start=False, memory_limit=2**30)
    garbage = b"ply\nformat ascii 1.0\nelement vertex banana\n"
    size = JobSize(n=100, dim=3, kind="cloud")
    rec = queue.submit(NewJob.check(garbage, "ply", PARAMS, size=size))
    assert rec.status is JobStatus.QUEUED and rec.params["tau"] == 1.0
    with pytest.raises(FormatError):
        queue.submit(NewJob.check(garbage, "ply", PARAMS))
    with pytest.raises(ValueError, match="unknown format"):
        NewJob.check(garbage, "svg", PARAMS)
