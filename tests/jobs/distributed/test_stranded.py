"""Issue 34 item 3 on the RQ backend: Redis refusing every write mid-run (``NOREPLICAS``, as a
full disk makes it refuse with ``MISCONF``): the run's progress and outcome cannot be written;
once writes work again the job leaves ``running`` within a bounded time and succeeds."""

from __future__ import annotations

import time
from pathlib import Path

from service.jobs import JobStatus
from service.jobs.config import RQConfig
from service.jobs.distributed.queue import RQQueue
from service.jobs.queue import NewJob
from tests.jobs.jobs_fakes import script
from tests.jobs.jobs_helpers import PARAMS, wait_finished, wait_for
from tests.jobs.rq_harness import RedisServer, WorkerProcess, rq_settings


def test_redis_refusing_writes_mid_run_never_strands_the_job(tmp_path: Path) -> None:
    from redis import Redis

    redis = RedisServer(tmp_path / "redis").start()
    settings = rq_settings(redis.url, tmp_path / "data", rq_queue_name="stranded")
    worker = WorkerProcess(settings, "s1", tmp_path / "s1.log").start()
    queue = RQQueue(RQConfig(settings, sweep_interval=0.2, reconcile_interval=2.0))
    queue.start()
    admin = Redis.from_url(redis.url)
    try:
        worker.wait_registered(queue.backend.redis)
        job = queue.submit(NewJob.check(script("sleep", seconds=3.0, steps=30), "json", PARAMS))
        wait_for(lambda: (r := queue.get(job.id)) and r.status is JobStatus.RUNNING, timeout=30)
        admin.config_set("min-replicas-to-write", 1)  # every write refused from now on
        time.sleep(6.0)  # past the run's end: its outcome cannot be written
        admin.config_set("min-replicas-to-write", 0)  # writes work again
        back = time.monotonic()
        left = wait_for(
            lambda: (r := queue.get(job.id)) and r.status is not JobStatus.RUNNING and r,
            timeout=60,
        )
        assert time.monotonic() - back < 60, left
        done = wait_finished(queue, job.id, timeout=120)  # type: ignore[arg-type]
        assert done.status is JobStatus.SUCCEEDED, (done.problem, worker.log.read_text()[-3000:])
    finally:
        admin.config_set("min-replicas-to-write", 0)
        queue.stop()
        worker.stop()
        redis.stop()
