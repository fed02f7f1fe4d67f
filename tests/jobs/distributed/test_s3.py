"""The S3 blob store against moto's S3 server (real HTTP), with a real worker and redis-server."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import httpx
import numpy as np
import pytest

from service.core.geometry import Geometry
from service.core.params import SmoothingParams
from service.core.pipeline import smooth_one as smooth
from service.io import GeometryDocument, read_geometry, write_geometry
from service.jobs import JobStatus
from service.jobs.config import RQConfig
from service.jobs.distributed.blobs import S3Blobs
from service.jobs.distributed.queue import RQQueue
from service.jobs.queue import NewJob
from tests.jobs.jobs_helpers import wait_finished
from tests.jobs.rq_harness import MotoServer, RedisServer, WorkerProcess, rq_settings

BUCKET = "geosmooth-test"


@pytest.fixture(scope="module")
def s3_cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Any]]:
    root = tmp_path_factory.mktemp("s3")
    moto = MotoServer().start()
    redis = RedisServer(root / "redis").start()
    aws = {"AWS_ENDPOINT_URL_S3": moto.url, "AWS_ACCESS_KEY_ID": "test",
           "AWS_SECRET_ACCESS_KEY": "test", "AWS_DEFAULT_REGION": "us-east-1"}  # fmt: skip
    mp = pytest.MonkeyPatch()
    for k, v in aws.items():
        mp.setenv(k, v)
    import boto3

    boto3.client("s3").create_bucket(Bucket=BUCKET)
    settings = rq_settings(redis.url, root / "api-cache", rq_queue_name="s3",
                           storage_url=f"s3://{BUCKET}/deploy", presign_seconds=60)  # fmt: skip
    worker_settings = settings.model_copy(update={"data_dir": root / "worker-scratch"})
    worker = WorkerProcess(worker_settings, "s3w", root / "s3w.log", extra_env=aws).start()
    queue = RQQueue(RQConfig(settings, sweep_interval=0.2))
    queue.start()
    try:
        worker.wait_registered(queue.backend.redis)
        yield {"queue": queue, "root": root, "redis": redis}
    finally:
        queue.stop()
        worker.stop()
        redis.stop()
        moto.stop()
        mp.undo()


def _cloud(seed: int) -> Geometry:
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, 1, (300, 2))
    return Geometry(np.c_[xy, 0.05 * np.sin(4 * xy[:, 0]) + rng.normal(0, 0.01, 300)])


def test_jobs_run_with_inputs_and_results_in_s3(s3_cluster: dict[str, Any]) -> None:
    queue: RQQueue = s3_cluster["queue"]
    assert isinstance(queue.blobs, S3Blobs)
    geometry = _cloud(5)
    params = SmoothingParams(rms=0.01)
    data = write_geometry(GeometryDocument.from_geometry(geometry), "ply")
    rec = queue.submit(NewJob.check(data, "ply", params, filename="scan.ply"))
    done = wait_finished(queue, rec.id, timeout=60)
    assert done.status is JobStatus.SUCCEEDED, done.problem
    keys = sorted(o["Key"] for o in queue.blobs.client.list_objects_v2(
        Bucket=BUCKET, Prefix=f"deploy/jobs/{rec.id}/")["Contents"])  # fmt: skip
    assert keys == [f"deploy/jobs/{rec.id}/{n}" for n in
                    ("input.ply", "report.json", "result.npy", "result.ply")]  # fmt: skip
    expected = smooth(read_geometry(data, "ply").geometry, params).points
    doc = queue.result(rec.id)
    assert doc is not None
    np.testing.assert_allclose(doc.geometry.points, expected, rtol=0, atol=1e-12)
    assert done.report is not None and done.report["phi"] == pytest.approx(
        float(np.sum((expected - geometry.points) ** 2)), rel=1e-9)  # fmt: skip

    local = queue.result_file(rec.id, "ply")  # downloaded once into the API's cache
    assert local is not None and local.is_relative_to(s3_cluster["root"] / "api-cache")
    url = queue.result_url(rec.id, "ply")
    assert url is not None and "X-Amz-Signature=" in url and "X-Amz-Expires=60" in url
    download = httpx.get(url, timeout=10)  # presigned: no credentials needed
    assert download.status_code == 200 and download.content == local.read_bytes()
    assert 'filename="scan.smoothed.ply"' in download.headers["content-disposition"]
    np.testing.assert_allclose(read_geometry(download.content, "ply").geometry.points, expected,
                               atol=1e-6)  # fmt: skip (float32 PLY)

    assert queue.delete(rec.id) is True
    listing = queue.blobs.client.list_objects_v2(Bucket=BUCKET, Prefix=f"deploy/jobs/{rec.id}/")
    assert listing.get("KeyCount", 0) == 0 and not local.exists()


def _value(redis: Any, key: bytes) -> bytes:
    """Everything stored under ``key``, as bytes."""
    kind = redis.type(key).decode()
    if kind == "string":
        return bytes(redis.get(key) or b"")
    if kind == "hash":
        return b"".join(k + v for k, v in redis.hgetall(key).items())
    if kind == "zset":
        return b"".join(m for m, _ in redis.zrange(key, 0, -1, withscores=True))
    if kind == "list":
        return b"".join(redis.lrange(key, 0, -1))
    if kind == "set":
        return b"".join(redis.smembers(key))
    return repr(redis.xrange(key)).encode() if kind == "stream" else b""


def test_no_geometry_travels_through_redis(s3_cluster: dict[str, Any]) -> None:
    queue: RQQueue = s3_cluster["queue"]
    marker = "0.123456789012345"  # a coordinate that appears in the input file only
    body = ("\n".join(f"{x} {y} 0.5" for x, y in np.random.default_rng(1).uniform(size=(200, 2)))
            + f"\n{marker} 0.25 0.5\n").encode()  # fmt: skip
    rec = queue.submit(NewJob.check(body, "xyz", SmoothingParams(rms=0.01)))
    assert wait_finished(queue, rec.id, timeout=60).status is JobStatus.SUCCEEDED
    redis = queue.backend.redis
    total = 0
    for key in redis.scan_iter(count=1000):
        value = _value(redis, key)
        total += len(value)
        assert marker.encode() not in value, key
    per_job = total / max(1, len(queue.list(limit=500)[0]))
    assert per_job < 16_000, per_job  # ids, params, progress, report-free records
