"""Run-time histogram of succeeded jobs: the one bucket set of the service.

Both queue backends report ``duration_buckets`` (cumulative ``[le, count]`` pairs ending with
``inf``), ``duration_sum`` and ``duration_count`` in ``stats()``; the API's synchronous-solve
histogram uses the same :data:`DURATION_BUCKETS`.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Sequence
from typing import Any

__all__ = ["DURATION_BUCKETS", "DurationHistogram", "bucket_index", "cumulative"]

DURATION_BUCKETS: tuple[float, ...] = (
    0.01, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0, 60.0, 120.0, 300.0, 600.0, 1800.0,
    3600.0,
)  # fmt: skip


def bucket_index(seconds: float) -> int:
    """Index of the first bucket holding ``seconds`` (``len(DURATION_BUCKETS)``: +Inf)."""
    return next((i for i, le in enumerate(DURATION_BUCKETS) if seconds <= le),
                len(DURATION_BUCKETS))  # fmt: skip


def cumulative(counts: Sequence[int]) -> list[list[float]]:
    """Per-bucket counts -> cumulative ``[le, count]`` pairs (``le`` ending with ``inf``)."""
    out, total = [], 0
    for le, n in zip((*DURATION_BUCKETS, float("inf")), counts, strict=True):
        total += int(n)
        out.append([le, total])
    return out


class DurationHistogram:
    """Run seconds of the jobs this process saw succeed (thread-safe)."""

    def __init__(self, keep: int = 1000) -> None:
        self._lock = threading.Lock()
        self._counts = [0] * (len(DURATION_BUCKETS) + 1)
        self._sum = 0.0
        self._recent: deque[float] = deque(maxlen=keep)

    def observe(self, seconds: float) -> None:
        """Count one run."""
        with self._lock:
            self._counts[bucket_index(seconds)] += 1
            self._sum += seconds
            self._recent.append(seconds)

    def stats(self) -> dict[str, Any]:
        """``durations`` (the last runs), ``duration_buckets``, ``duration_sum``,
        ``duration_count``."""
        with self._lock:
            buckets = cumulative(self._counts)
            return {
                "durations": list(self._recent),
                "duration_buckets": buckets,
                "duration_sum": self._sum,
                "duration_count": int(buckets[-1][1]),
            }
