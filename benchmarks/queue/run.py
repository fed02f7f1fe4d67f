"""The measurements of ``python -m benchmarks.queue``.

* **Throughput** of a job mix (real smoothing jobs: polylines of 50k-100k points, meshes of 10k
  and 41k vertices, clouds of 15k-30k points, 0.3-3 s each on one core) on 1 and 2 workers, RQ
  and embedded: the whole mix submitted at once; jobs/s = jobs / makespan (first submit to last
  finish); p50/p95 of each job's latency (submit to finish, from the records' timestamps);
  scaling ratio = throughput(2) / throughput(1); worker utilization = summed run seconds /
  (workers x makespan), which separates the queue's share from CPU contention.
* **Overhead per job**: tiny jobs (a 12-point ring) submitted one at a time and waited for, RQ vs
  embedded, 1 worker: the difference of the median submit-to-finish latencies.
* **Redis cost per job**: commands (``INFO stats``) and redis-server CPU seconds
  (``/proc/<pid>/stat``) per job of the mix, for the paper estimate at 10 and 100 workers.
"""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.queue.cluster import Cluster
from service.core.geometry import Geometry
from service.core.params import SmoothingParams
from service.io import GeometryDocument, write_geometry
from service.jobs import JobQueue, JobRecord
from service.jobs.config import LocalConfig, RQConfig
from service.jobs.distributed.queue import RQQueue
from service.jobs.embedded.queue import LocalQueue
from service.jobs.queue import NewJob

__all__ = ["job_mix", "overhead", "redis_cost", "throughput"]

Job = tuple[bytes, str, SmoothingParams]


def _ring(n: int, seed: int) -> Geometry:
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    pts = np.c_[np.cos(t), np.sin(t), 0.1 * np.sin(5 * t)] + rng.normal(0, 0.01, (n, 3))
    return Geometry(pts, edges=np.c_[np.arange(n), (np.arange(n) + 1) % n])


def _sphere(subdivisions: int, seed: int) -> Geometry:
    import trimesh

    s = trimesh.creation.icosphere(subdivisions=subdivisions)
    rng = np.random.default_rng(seed)
    return Geometry(s.vertices + rng.normal(0, 0.005, s.vertices.shape), np.asarray(s.faces))


def _cloud(n: int, seed: int) -> Geometry:
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, 1, (n, 2))
    return Geometry(np.c_[xy, 0.05 * np.sin(6 * xy[:, 0]) + rng.normal(0, 0.005, n)])


def _job(geometry: Geometry, fmt: str, params: SmoothingParams) -> Job:
    return write_geometry(GeometryDocument.from_geometry(geometry), fmt), fmt, params


def job_mix(repeat: int = 2) -> list[Job]:
    """The mix: per repeat, 2 polylines, 2 meshes, 2 clouds (12 jobs by default)."""
    out = []
    for r in range(repeat):
        out += [
            _job(_ring(50_000, r), "obj", SmoothingParams(rms=0.005)),
            _job(_ring(100_000, r + 10), "obj", SmoothingParams(rms=0.005)),
            _job(_sphere(5, r), "ply", SmoothingParams(rms=0.002)),
            _job(_sphere(6, r), "ply", SmoothingParams(rms=0.002)),
            _job(_cloud(15_000, r), "xyz", SmoothingParams(rms=0.003)),
            _job(_cloud(30_000, r), "xyz", SmoothingParams(rms=0.003)),
        ]
    return out


def _wait_all(queue: JobQueue, ids: list[str], timeout: float = 900.0) -> list[JobRecord]:
    deadline = time.monotonic() + timeout
    while True:
        recs = [queue.get(j) for j in ids]
        if all(r is not None and r.finished for r in recs):
            return [r for r in recs if r is not None]
        if time.monotonic() > deadline:
            raise RuntimeError("jobs did not finish")
        time.sleep(0.1)  # latencies come from the records' timestamps, not from this poll


def _run_mix(queue: JobQueue, jobs: list[Job]) -> dict[str, float]:
    t0 = time.time()
    ids = [queue.submit(NewJob.check(data, fmt, params)).id for data, fmt, params in jobs]
    recs = _wait_all(queue, ids)
    failed = [r.problem for r in recs if r.status.value != "succeeded"]
    if failed:
        raise RuntimeError(f"benchmark jobs failed: {failed[:3]}")
    end = max(r.finished_at or 0.0 for r in recs)
    latencies = sorted((r.finished_at or 0.0) - r.created_at for r in recs)
    return {
        "jobs": len(recs),
        "makespan_s": end - t0,
        "jobs_per_s": len(recs) / (end - t0),
        "p50_s": float(np.percentile(latencies, 50)),
        "p95_s": float(np.percentile(latencies, 95)),
        "run_s": float(sum(r.run_seconds or 0.0 for r in recs)),
    }


def utilization(run: dict[str, float], workers: int) -> float:
    """Share of the makespan the workers spent running jobs (1: the queue never idled them)."""
    return run["run_s"] / (workers * run["makespan_s"])


def _rq(root: Path, workers: int, name: str) -> tuple[Cluster, RQQueue]:
    cluster = Cluster(root / name, workers, name).start()
    queue = RQQueue(RQConfig(cluster.settings, sweep_interval=1.0))
    queue.start()
    return cluster, queue


def throughput(jobs: list[Job], workers: int, backend: str, rounds: int) -> dict[str, Any]:
    """Medians over ``rounds`` runs of the mix on ``workers`` workers of ``backend``."""
    runs = []
    with tempfile.TemporaryDirectory(prefix="bench-queue-") as tmp:
        if backend == "rq":
            cluster, queue = _rq(Path(tmp), workers, f"tp{workers}")
            try:
                _run_mix(queue, jobs[:2])  # warm up (imports, caches)
                runs = [_run_mix(queue, jobs) for _ in range(rounds)]
            finally:
                queue.stop()
                cluster.stop()
        else:
            local = LocalQueue(LocalConfig(Path(tmp) / "data", workers=workers, threads_per_job=1,
                                           sweep_interval=5.0))  # fmt: skip
            with local:
                _run_mix(local, jobs[:2])
                runs = [_run_mix(local, jobs) for _ in range(rounds)]
    return {key: statistics.median(r[key] for r in runs) for key in runs[0]} | {"rounds": runs}


def overhead(n_jobs: int = 30) -> dict[str, Any]:
    """Median submit-to-finish latency of tiny sequential jobs, embedded vs RQ (1 worker)."""
    tiny = _job(_ring(12, 0), "xyz", SmoothingParams(lam=0.5))
    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory(prefix="bench-overhead-") as tmp:
        local = LocalQueue(LocalConfig(Path(tmp) / "local", workers=1, threads_per_job=1,
                                       sweep_interval=5.0))  # fmt: skip
        cluster, rq_queue = _rq(Path(tmp), 1, "overhead")
        try:
            with local:
                for name, queue in (("embedded", local), ("rq", rq_queue)):
                    lat = []
                    for _ in range(n_jobs + 3):
                        t0 = time.time()
                        rec = _wait_all(queue, [queue.submit(NewJob.check(*tiny)).id])[0]
                        lat.append(((rec.finished_at or t0) - t0, rec.run_seconds or 0.0))
                    lat = lat[3:]  # warm-up
                    out[name] = {"latency_s": statistics.median(x for x, _ in lat),
                                 "run_s": statistics.median(r for _, r in lat)}  # fmt: skip
        finally:
            rq_queue.stop()
            cluster.stop()
    out["rq_overhead_per_job_s"] = out["rq"]["latency_s"] - out["embedded"]["latency_s"]
    return out


def _cpu_seconds(pid: int) -> float:
    import os

    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def redis_cost(jobs: list[Job]) -> dict[str, Any]:
    """Redis commands, CPU seconds and bytes stored per job of the mix (1 worker, the API's
    sweep running, the client polling only the 5 status counts once a second)."""
    with tempfile.TemporaryDirectory(prefix="bench-redis-") as tmp:
        cluster, queue = _rq(Path(tmp), 1, "cost")
        try:
            redis = queue.backend.redis
            _run_mix(queue, jobs[:2])
            done0 = queue.store.counts()["succeeded"]
            before = int(redis.info("stats")["total_commands_processed"])
            cpu0 = _cpu_seconds(cluster.redis_pid())
            mem0 = int(redis.info("memory")["used_memory"])
            t0 = time.time()
            for data, fmt, params in jobs:
                queue.submit(NewJob.check(data, fmt, params))
            polls = 0
            while queue.store.counts()["succeeded"] < done0 + len(jobs):
                polls += 1
                time.sleep(1.0)
            seconds = time.time() - t0
            commands = int(redis.info("stats")["total_commands_processed"]) - before - 5 * polls
            cpu = _cpu_seconds(cluster.redis_pid()) - cpu0
            mem = int(redis.info("memory")["used_memory"]) - mem0
        finally:
            queue.stop()
            cluster.stop()
    n = len(jobs)
    return {"commands_per_job": commands / n, "redis_cpu_s_per_job": cpu / n,
            "redis_bytes_per_job": mem / n, "seconds": seconds}  # fmt: skip
