"""Prometheus metrics with a per-app registry.

Job counts, queue depth, worker use and job solve durations are read from ``JobQueue.stats()`` at
scrape time (counts come from the job store, so they are right after a restart); synchronous
solves of ``POST /v1/smooth`` are observed directly, in the same buckets as the jobs'.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator
from typing import Any

from prometheus_client import CollectorRegistry, Counter, Histogram, generate_latest
from prometheus_client.core import (
    CounterMetricFamily,
    GaugeMetricFamily,
    HistogramMetricFamily,
    Metric,
)
from prometheus_client.registry import Collector

from service.jobs.metrics import DURATION_BUCKETS
from service.jobs.queue import JobQueue, JobStatus

__all__ = ["BUCKETS", "Metrics", "QueueCollector"]

#: The one bucket set of every duration histogram (job runs, synchronous solves).
BUCKETS: tuple[float, ...] = DURATION_BUCKETS
log = logging.getLogger("geosmooth.api")


class QueueCollector(Collector):
    """Collects job metrics from ``queue.stats()`` at scrape time.

    Parameters
    ----------
    queue_getter : callable
        Returns the app's queue, or ``None`` while it is not running.
    """

    def __init__(self, queue_getter: Callable[[], JobQueue | None]) -> None:
        self._queue_getter = queue_getter

    def describe(self) -> list[Metric]:
        return []

    def collect(self) -> Iterator[Metric]:
        queue = self._queue_getter()
        stats: dict[str, Any] = {}
        if queue is not None:
            try:
                stats = queue.stats()
            except Exception:  # a scrape must never fail because of the queue
                log.exception("queue.stats() failed")
        counts = stats.get("counts") or {}
        jobs = GaugeMetricFamily(
            "geosmooth_jobs", "Jobs in the job store by status.", labels=["status"]
        )
        for status in JobStatus:
            jobs.add_metric([status.value], float(counts.get(status.value, 0)))
        yield jobs
        depth = stats.get("queue_depth", counts.get(JobStatus.QUEUED.value, 0))
        yield GaugeMetricFamily(
            "geosmooth_queue_depth", "Jobs waiting for a worker.", value=float(depth or 0)
        )
        workers = GaugeMetricFamily(
            "geosmooth_workers", "Solver worker slots of this server.", labels=["state"]
        )
        workers.add_metric(["total"], float(stats.get("workers", 0) or 0))
        workers.add_metric(["busy"], float(stats.get("busy_workers", 0) or 0))
        yield workers
        finished = CounterMetricFamily(
            "geosmooth_jobs_finished",
            "Job runs this server saw end, by outcome (since the server started).",
            labels=["status"],
        )
        for status, count in sorted((stats.get("finished_total") or {}).items()):
            finished.add_metric([str(status)], float(count))
        yield finished
        yield _solve_histogram(stats)


def _solve_histogram(stats: dict[str, Any]) -> HistogramMetricFamily:
    hist = HistogramMetricFamily(
        "geosmooth_job_solve_seconds",
        "Run time of succeeded jobs in the worker (read, smooth, write), seconds.",
    )
    cumulative = stats.get("duration_buckets") or [(float("inf"), 0)]
    buckets = [
        ("+Inf" if le == float("inf") else repr(float(le)), float(count))
        for le, count in cumulative
    ]
    hist.add_metric([], buckets, float(stats.get("duration_sum", 0.0)))
    return hist


class Metrics:
    """The metrics of one app (own registry, so several apps can live in one process).

    Parameters
    ----------
    queue_getter : callable
        Returns the app's queue, or ``None`` while it is not running.
    """

    def __init__(self, queue_getter: Callable[[], JobQueue | None]) -> None:
        self.registry = CollectorRegistry(auto_describe=False)
        self.registry.register(QueueCollector(queue_getter))
        self.sync_solve_seconds = Histogram(
            "geosmooth_sync_solve_seconds",
            "Duration of synchronous solves (POST /v1/smooth), seconds.",
            buckets=BUCKETS,
            registry=self.registry,
        )
        self.jobs_submitted = Counter(
            "geosmooth_jobs_submitted",
            "Jobs accepted by POST /v1/jobs since the server started.",
            registry=self.registry,
        )

    def render(self) -> bytes:
        """The Prometheus text exposition of every metric."""
        return generate_latest(self.registry)
