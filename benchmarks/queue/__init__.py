"""Throughput and per-job overhead of the job queues (``python -m benchmarks.queue``)."""
