"""The RQ backend when things die: a worker (SIGKILL), Redis (SIGKILL + restart), the API."""

from __future__ import annotations

import itertools
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

from service.jobs import JobStatus
from service.jobs.config import RQConfig
from service.jobs.distributed.queue import RQQueue
from service.jobs.queue import NewJob
from tests.jobs.jobs_fakes import script
from tests.jobs.jobs_helpers import PARAMS, REPO, pid_gone, wait_finished, wait_for
from tests.jobs.rq_harness import (
    RedisServer,
    WorkerProcess,
    free_port,
    rq_settings,
    runs,
    settings_env,
)
from tests.timing import patience


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Any]]:
    """redis-server (append-only, fsync always), two workers, the API-side queue."""
    root = tmp_path_factory.mktemp("rqfail")
    redis = RedisServer(root / "redis").start()
    settings = rq_settings(redis.url, root / "data", job_timeout=4.0, rq_queue_name="failover")
    workers = [WorkerProcess(settings, f"f{i}", root / f"f{i}.log").start() for i in (1, 2)]
    queue = RQQueue(RQConfig(settings, sweep_interval=0.2, reconcile_interval=2.0))
    queue.start()
    state = {"queue": queue, "workers": workers, "settings": settings, "root": root,
             "redis": redis}  # fmt: skip
    try:
        for w in workers:
            w.wait_registered(queue.backend.redis)
        yield state
    finally:
        queue.stop()
        for w in state["workers"]:
            w.stop()
        redis.stop()


def _job_dir(cluster: dict[str, Any], job_id: str) -> Path:
    return Path(cluster["settings"].data_dir) / "jobs" / job_id


def _no_overlap(cluster: dict[str, Any], job_id: str) -> list[tuple[int, float, float | None]]:
    """The runs of a job, checked to never overlap (a killed run ends when its pid is gone)."""
    found = runs(_job_dir(cluster, job_id))
    for (_, start1, end1), (_, start2, _) in itertools.pairwise(found):
        assert start2 > start1 and (end1 is None or start2 >= end1)
    return found


def test_sigkill_of_a_worker_mid_job_reruns_it_on_the_other(cluster: dict[str, Any]) -> None:
    queue: RQQueue = cluster["queue"]
    ids = [queue.submit(NewJob.check(script("sleep", seconds=2.5, steps=10), "json", PARAMS)).id
           for _ in range(2)]  # fmt: skip

    def both_running() -> list[Any] | None:
        recs = [queue.get(j) for j in ids]
        ok = all(r and r.status is JobStatus.RUNNING and r.pid for r in recs)
        return recs if ok and all(runs(_job_dir(cluster, j)) for j in ids) else None

    recs = wait_for(both_running, timeout=20)
    victim = cluster["workers"][0]
    raw = {r.id: queue.store.raw(r.id) for r in recs}
    killed = next(r for r in recs if raw[r.id]["owner"] == victim.name)
    horse = killed.pid
    victim.kill(signal.SIGKILL)  # the worker process, not its horse
    wait_for(lambda: pid_gone(horse), timeout=5)  # the horse died with its worker
    dead_at = time.time()
    done = {j: wait_finished(queue, j, timeout=40) for j in ids}
    assert all(r.status is JobStatus.SUCCEEDED for r in done.values()), done
    assert done[killed.id].attempts == 2
    survivor = next(j for j in ids if j != killed.id)
    assert done[survivor].attempts == 1
    found = _no_overlap(cluster, killed.id)
    assert len(found) == 2 and found[0][2] is None and found[1][1] >= dead_at
    assert found[0][0] == horse
    replacement = WorkerProcess(cluster["settings"], "f3", cluster["root"] / "f3.log").start()
    cluster["workers"][0] = replacement  # for the next tests


def test_sigterm_of_a_worker_requeues_its_job_without_counting_a_try(
    cluster: dict[str, Any],
) -> None:
    queue: RQQueue = cluster["queue"]
    rec = queue.submit(NewJob.check(script("sleep", seconds=2.0, steps=8), "json", PARAMS))
    running = wait_for(lambda: (r := queue.get(rec.id)) and r.status is JobStatus.RUNNING
                       and r.pid and runs(_job_dir(cluster, rec.id)) and r, timeout=20)  # fmt: skip
    owner = queue.store.raw(rec.id)["owner"]  # type: ignore[index]
    index = next(i for i, w in enumerate(cluster["workers"]) if w.name == owner)
    stopped = cluster["workers"][index]
    stopped.kill(signal.SIGTERM)  # docker stop: the worker exits, its job goes back
    assert stopped.proc is not None and stopped.proc.returncode == 0
    assert pid_gone(running.pid)
    done = wait_finished(queue, rec.id, timeout=30)
    assert done.status is JobStatus.SUCCEEDED and done.attempts == 1  # not charged a try
    assert len(_no_overlap(cluster, rec.id)) == 2
    log = cluster["root"] / f"{owner}r.log"
    cluster["workers"][index] = WorkerProcess(cluster["settings"], f"{owner}r", log).start()


def test_timeout_kills_a_run_stuck_anywhere(cluster: dict[str, Any]) -> None:
    queue: RQQueue = cluster["queue"]
    rec = queue.submit(NewJob.check(script("sleep", seconds=60), "json", PARAMS))
    running = wait_for(lambda: (r := queue.get(rec.id)) and r.pid and r, timeout=30)
    done = wait_finished(queue, rec.id, timeout=20)
    assert done.status is JobStatus.FAILED and done.problem["code"] == "timeout"  # type: ignore[index]
    # stopped at its 4 s timeout, not after the 60 s it sleeps (a busy machine stops it later)
    assert 4.0 <= done.finished_at - done.started_at < 30.0  # type: ignore[operator]
    assert done.attempts == 1 and pid_gone(running.pid)


def test_redis_killed_and_restarted_loses_no_job(cluster: dict[str, Any]) -> None:
    queue: RQQueue = cluster["queue"]
    redis: RedisServer = cluster["redis"]
    for w in cluster["workers"]:
        w.wait_registered(queue.backend.redis)
    long = [queue.submit(NewJob.check(script("sleep", seconds=2.0, steps=8), "json", PARAMS)).id
            for _ in range(2)]  # fmt: skip
    short = [queue.submit(NewJob.check(script("ok", steps=2), "json", PARAMS)).id for _ in range(4)]
    wait_for(lambda: all((r := queue.get(j)) and r.status is JobStatus.RUNNING for j in long),
             timeout=20)  # fmt: skip
    redis.kill()  # SIGKILL: only the append-only file survives
    time.sleep(0.5)
    redis.start()
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        states = {j: queue.store.raw(j) for j in long + short}
        if all(s and s["status"] in ("succeeded", "failed", "cancelled") for s in states.values()):
            break
        time.sleep(0.1)
    assert all(s["status"] == "succeeded" for s in states.values()), states  # type: ignore[index]
    done = {j: wait_finished(queue, j) for j in long + short}
    for j in long + short:
        _no_overlap(cluster, j)
    assert all(done[j].attempts == 1 for j in short)


def _api(settings_env_: dict[str, str], port: int, log: Path) -> subprocess.Popen[bytes]:
    args = [sys.executable, "-m", "service.api.server", "--host", "127.0.0.1", "--port",
            str(port)]  # fmt: skip
    with open(log, "ab") as out:
        proc = subprocess.Popen(args, env=settings_env_, cwd=REPO, stdout=out, stderr=out)

    def ready() -> bool:
        try:
            return httpx.get(f"http://127.0.0.1:{port}/readyz", timeout=1).status_code == 200
        except httpx.TransportError:
            return False

    wait_for(ready, timeout=60, interval=0.1)
    return proc


def test_api_killed_and_restarted_loses_nothing(cluster: dict[str, Any]) -> None:
    env = settings_env(cluster["settings"])
    port = free_port()
    log = cluster["root"] / "api.log"
    api = _api(env, port, log)
    url = f"http://127.0.0.1:{port}"
    try:
        ids = []
        for i in range(8):  # real smoothing jobs (the API parses the upload)
            points = np.random.default_rng(i).normal(size=(400, 3))
            body = "\n".join(" ".join(f"{v:.6f}" for v in p) for p in points).encode()
            files = {"file": (f"cloud{i}.xyz", body, "text/plain")}
            r = httpx.post(f"{url}/v1/jobs", files=files, data={"params": '{"rms": 0.05}'},
                           timeout=patience(10))  # fmt: skip
            assert r.status_code == 202, r.text
            ids.append(r.json()["id"])
        os.kill(api.pid, signal.SIGKILL)  # while jobs are queued and running
        api.wait(10)
        api = _api(env, port, log)
        for job_id in ids:
            def finished(job_id: str = job_id) -> dict[str, Any] | None:
                job = httpx.get(f"{url}/v1/jobs/{job_id}", timeout=patience(5)).json()
                return job if job["status"] in ("succeeded", "failed", "cancelled") else None

            job = wait_for(finished, timeout=40, interval=0.1)
            assert job["status"] == "succeeded" and job["attempts"] == 1, job
            result = httpx.get(f"{url}/v1/jobs/{job_id}/result", timeout=patience(10))
            assert result.status_code == 200
    finally:
        if api.poll() is None:
            api.terminate()
            api.wait(15)
