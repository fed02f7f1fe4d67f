"""The RQ backend against a real redis-server and two real RQ worker processes."""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from service.core.geometry import Geometry
from service.core.params import SmoothingParams
from service.io import GeometryDocument, write_geometry
from service.jobs import JobQueue, JobStatus, LocalQueue
from service.jobs.config import RQConfig
from service.jobs.distributed.backend import Backend
from service.jobs.distributed.queue import RQQueue
from service.jobs.queue import NewJob
from service.jobs.runner import DEFAULT_RUNNER
from tests.jobs.jobs_fakes import script
from tests.jobs.jobs_helpers import PARAMS, pid_gone, wait_finished, wait_for
from tests.jobs.jobs_receiver import Receiver, documented_verifier
from tests.jobs.rq_harness import WEBHOOK_SECRET, RedisServer, WorkerProcess, rq_settings, runs

MakeQueue = Callable[..., LocalQueue]


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Any]]:
    """redis-server, two workers and the API-side queue, shared by this module's tests."""
    root = tmp_path_factory.mktemp("rq")
    redis = RedisServer(root / "redis").start()
    settings = rq_settings(redis.url, root / "data")
    workers = [WorkerProcess(settings, f"w{i}", root / f"w{i}.log").start() for i in (1, 2)]
    queue = RQQueue(RQConfig(settings, sweep_interval=0.2))
    queue.start()
    try:
        for w in workers:
            w.wait_registered(queue.backend.redis)
        yield {"queue": queue, "workers": workers, "settings": settings, "root": root}
    finally:
        queue.stop()
        for w in workers:
            w.stop()
        redis.stop()


def _queue(cluster: dict[str, Any]) -> RQQueue:
    return cluster["queue"]  # type: ignore[no-any-return]


def _ring(seed: int, n: int = 120) -> Geometry:
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    points = np.c_[np.cos(t), np.sin(t), 0.1 * np.sin(3 * t)] + rng.normal(0.0, 0.02, (n, 3))
    return Geometry(points, edges=np.c_[np.arange(n), (np.arange(n) + 1) % n])


def _inputs() -> list[tuple[bytes, str, SmoothingParams]]:
    """20 real jobs: four formats, tau and rms targets, point clouds and polylines."""
    out = []
    for i in range(20):
        fmt = ("obj", "xyz", "ply", "json")[i % 4]
        geometry = _ring(i, 80 + 10 * (i % 5))
        if fmt == "xyz":  # XYZ holds points only: the ring's points as a cloud
            geometry = Geometry(geometry.points)
        params = SmoothingParams(tau=0.02 + 0.005 * (i % 3)) if i % 2 else SmoothingParams(
            rms=0.01)  # fmt: skip
        data = write_geometry(GeometryDocument.from_geometry(geometry), fmt)
        out.append((data, fmt, params))
    return out


def test_rq_queue_implements_the_protocol(cluster: dict[str, Any]) -> None:
    assert isinstance(_queue(cluster), JobQueue)


def test_twenty_jobs_from_four_threads_equal_the_embedded_results(
    cluster: dict[str, Any], make_queue: MakeQueue
) -> None:
    queue = _queue(cluster)
    inputs = _inputs()
    ids: dict[int, str] = {}
    errors: list[BaseException] = []

    def client(indices: range) -> None:
        try:
            for i in indices:
                data, fmt, params = inputs[i]
                ids[i] = queue.submit(NewJob.check(data, fmt, params, filename=f"in{i}.{fmt}")).id
        except BaseException as exc:  # pragma: no cover - reported below
            errors.append(exc)

    threads = [threading.Thread(target=client, args=(range(k, 20, 4),)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors and len(set(ids.values())) == 20
    local = make_queue(runner=DEFAULT_RUNNER)
    local_ids = {i: local.submit(NewJob.check(*inputs[i])).id for i in range(20)}
    remote = {i: wait_finished(queue, j, timeout=60) for i, j in ids.items()}
    embedded = {i: wait_finished(local, j, timeout=60) for i, j in local_ids.items()}
    data_dir = Path(cluster["settings"].data_dir)
    for i in range(20):
        assert remote[i].status is JobStatus.SUCCEEDED, remote[i].problem
        assert remote[i].attempts == 1  # each ran once
        ours = np.load(data_dir / "jobs" / ids[i] / "result.npy")
        theirs = np.load(local.files.result_points(local_ids[i]))
        np.testing.assert_array_equal(ours, theirs)
        assert remote[i].report["phi"] == embedded[i].report["phi"]  # type: ignore[index]
        doc = queue.result(ids[i])
        assert doc is not None
        np.testing.assert_array_equal(doc.geometry.points, ours)
        path = queue.result_file(ids[i], inputs[i][1])
        assert path is not None and path.read_bytes() == local.result_file(
            local_ids[i], inputs[i][1]).read_bytes()  # type: ignore[union-attr]  # fmt: skip
    stats = queue.stats()
    assert stats["workers"] == 2 and stats["counts"]["succeeded"] >= 20
    assert stats["duration_count"] >= 20


def test_progress_of_a_remote_run_is_visible(cluster: dict[str, Any]) -> None:
    queue = _queue(cluster)
    rec = queue.submit(NewJob.check(script("sleep", seconds=1.5, steps=10), "json", PARAMS))
    assert rec.progress is not None and rec.progress["stage"] == "queued"
    seen: list[dict[str, Any]] = []
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        cur = queue.get(rec.id)
        assert cur is not None
        if cur.status is JobStatus.RUNNING and cur.progress:
            seen.append(dict(cur.progress))
        if cur.finished:
            break
        time.sleep(0.03)
    iterations = [p["iteration"] for p in seen if p["stage"] == "search"]
    assert any(1 <= i < 10 for i in iterations) and iterations == sorted(iterations)
    assert all(p["relative_error"] > 0 and 40 <= p["percent"] <= 90 for p in seen
               if p["stage"] == "search")  # fmt: skip
    done = queue.get(rec.id)
    assert done is not None and done.status is JobStatus.SUCCEEDED and done.iteration == 10


def test_cancel_kills_the_remote_run(cluster: dict[str, Any]) -> None:
    queue = _queue(cluster)
    rec = queue.submit(NewJob.check(script("sleep", seconds=30), "json", PARAMS))
    running = wait_for(lambda: (r := queue.get(rec.id)) and r.status is JobStatus.RUNNING
                       and r.pid and r, timeout=20)  # fmt: skip
    pid = running.pid
    assert not pid_gone(pid)
    t0 = time.monotonic()
    cancelled = queue.cancel(rec.id)
    assert time.monotonic() - t0 < 15  # a kill, not the 30 s of the job (any load)
    assert cancelled is not None and cancelled.status is JobStatus.CANCELLED
    assert pid_gone(pid)  # the work horse is gone when cancel returns
    follow = queue.submit(
        NewJob.check(script("ok"), "json", PARAMS)
    )  # both workers still take jobs
    assert wait_finished(queue, follow.id, 20).status is JobStatus.SUCCEEDED
    time.sleep(0.3)
    assert queue.get(rec.id).status is JobStatus.CANCELLED  # type: ignore[union-attr]


def test_cancel_of_a_queued_remote_job(cluster: dict[str, Any]) -> None:
    queue = _queue(cluster)
    blockers = [
        queue.submit(NewJob.check(script("sleep", seconds=3), "json", PARAMS)) for _ in range(2)
    ]
    waiting = queue.submit(NewJob.check(script("ok"), "json", PARAMS))
    assert queue.cancel(waiting.id).status is JobStatus.CANCELLED  # type: ignore[union-attr]
    for b in blockers:
        assert wait_finished(queue, b.id, 20).status is JobStatus.SUCCEEDED
    data_dir = Path(cluster["settings"].data_dir)
    assert not (data_dir / "jobs" / waiting.id / "pids").exists()  # never ran


def test_crashes_fail_input_errors_fail_oom_kill_is_retried(cluster: dict[str, Any]) -> None:
    queue = _queue(cluster)
    jobs = {name: queue.submit(NewJob.check(script(name), "json", PARAMS)).id
            for name in ("segfault", "core_error", "raise", "oom_once")}  # fmt: skip
    done = {name: wait_finished(queue, j, timeout=30) for name, j in jobs.items()}
    assert done["segfault"].status is JobStatus.FAILED and done["segfault"].attempts == 1
    assert "SIGSEGV" in done["segfault"].problem["detail"]  # type: ignore[index]
    assert done["core_error"].problem["code"] == "tau-out-of-range"  # type: ignore[index]
    assert done["core_error"].attempts == 1  # input errors are never retried
    assert done["raise"].problem["code"] == "internal-error"  # type: ignore[index]
    oom = done["oom_once"]
    assert oom.status is JobStatus.SUCCEEDED and oom.attempts == 2  # killed once, run again
    job_dir = Path(cluster["settings"].data_dir) / "jobs" / jobs["oom_once"]
    (first, _, end1), (second, _, _) = runs(job_dir)
    assert end1 is None and first != second  # the first run was killed mid-way


def test_tenants_and_idempotency_through_redis(cluster: dict[str, Any]) -> None:
    queue = _queue(cluster)
    a = queue.submit(
        NewJob.check(script("ok"), "json", PARAMS, tenant="a" * 16, idempotency_key="k")
    )
    again = queue.submit(
        NewJob.check(script("ok"), "json", PARAMS, tenant="a" * 16, idempotency_key="k")
    )
    assert again.id == a.id
    from service.jobs.errors import IdempotencyConflict

    with pytest.raises(IdempotencyConflict):
        queue.submit(
            NewJob.check(
                script("ok", steps=9), "json", PARAMS, tenant="a" * 16, idempotency_key="k"
            )
        )
    b = queue.submit(
        NewJob.check(script("ok"), "json", PARAMS, tenant="b" * 16, idempotency_key="k")
    )
    assert b.id != a.id
    assert queue.get(b.id, tenant="a" * 16) is None and queue.get(a.id, tenant="a" * 16)
    page, total = queue.list(tenant="b" * 16)
    assert total == 1 and page[0].id == b.id
    wait_finished(queue, a.id, 20)
    assert queue.delete(a.id, tenant="b" * 16) is False
    assert queue.delete(a.id, tenant="a" * 16) is True and queue.get(a.id) is None
    data_dir = Path(cluster["settings"].data_dir)
    assert not (data_dir / "jobs" / a.id).exists()
    c = queue.submit(
        NewJob.check(script("ok"), "json", PARAMS, tenant="a" * 16, idempotency_key="k")
    )
    assert c.id != a.id  # the key went with the deleted job


def test_health_and_metrics_from_redis(cluster: dict[str, Any]) -> None:
    queue = _queue(cluster)
    health = queue.health()
    assert health.ok and health.checks == {"broker": "ok", "storage": "ok", "workers": "ok"}
    stats = queue.stats()
    assert stats["workers"] == 2 and stats["queue_depth"] >= 0
    assert set(stats["finished_total"]) == {"succeeded", "failed", "cancelled"}


def test_the_worker_that_finished_a_job_posts_its_webhook(cluster: dict[str, Any]) -> None:
    queue = _queue(cluster)
    verify = documented_verifier()
    with Receiver([502, 200]) as hook:
        rec = queue.submit(NewJob.check(script("ok"), "json", PARAMS, webhook_url=hook.url()))
        done = wait_finished(queue, rec.id, 120)  # generous: a busy machine is slow, not wrong
        wait_for(lambda: len(hook.deliveries) == 2, timeout=120)
        # the state is written after the 200 is read: wait for it, do not race it
        wait_for(lambda: queue.store.raw(rec.id)["webhook_state"] == "delivered", timeout=60)  # type: ignore[index]
    last = hook.deliveries[-1]
    assert verify(WEBHOOK_SECRET, last.body, last.headers["Geosmooth-Signature"])
    assert json.loads(last.body) == done.public_dict()


def test_ttl_expiry_removes_records_and_blobs(cluster: dict[str, Any]) -> None:
    queue = _queue(cluster)
    rec = queue.submit(NewJob.check(script("ok"), "json", PARAMS, idempotency_key="ttl-key"))
    assert wait_finished(queue, rec.id, 20).status is JobStatus.SUCCEEDED
    job_dir = Path(cluster["settings"].data_dir) / "jobs" / rec.id
    assert job_dir.exists()
    short = Backend.connect(cluster["settings"].model_copy(update={"result_ttl": 0.3}))
    time.sleep(0.4)
    assert rec.id in short.expire()
    assert queue.get(rec.id) is None and not job_dir.exists()
    assert queue.store.redis.exists(queue.store.key(rec.id)) == 0
    assert all(queue.store.redis.zscore(queue.store.index(None, s), rec.id) is None
               for s in (None, "succeeded"))  # fmt: skip
    again = queue.submit(NewJob.check(script("ok"), "json", PARAMS, idempotency_key="ttl-key"))
    assert again.id != rec.id  # the idempotency key expired with its job
