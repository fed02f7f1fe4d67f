"""The instance epoch of the Redis data: tells a Redis that came back empty from one that was
only unreachable.

A random token is written once under ``<prefix>:epoch`` (``SET NX``) and remembered by every
API process that saw it. Redis restarted from its append-only file keeps it; a Redis that lost
its data (no persistence, a deleted volume, a fail-over to an empty replica) comes back without
it, and every queued job with it. The first look after that (the sweeper's, every
``sweep_interval``, or ``/readyz``) logs ``broker.restarted_empty`` at error level, writes a new
epoch, and ``/readyz`` reports ``broker: restarted-empty`` (503) for :data:`REPORT_SECONDS`, so
that a load balancer and an operator see it; then the new epoch is the normal state again.
"""

from __future__ import annotations

import logging
import threading
import time
import uuid
from typing import Any

__all__ = ["REPORT_SECONDS", "Epoch"]

log = logging.getLogger("geosmooth.jobs")

#: Seconds ``/readyz`` reports a Redis that came back empty.
REPORT_SECONDS = 300.0


class Epoch:
    """The epoch token of one Redis key space (see the module docstring)."""

    def __init__(self, redis: Any, key: str) -> None:
        self.redis = redis
        self.key = key
        self.token: bytes | None = None
        self.lost_at: float | None = None
        self._lock = threading.Lock()

    def _current(self) -> bytes:
        """The stored token, written first when there is none."""
        self.redis.set(self.key, uuid.uuid4().hex, nx=True)
        value = self.redis.get(self.key)
        return bytes(value) if value is not None else b""

    def check(self) -> str:
        """``"ok"``, or ``"restarted-empty"`` while the last loss is recent (raises the Redis
        client's error when Redis cannot be reached)."""
        with self._lock:
            value = self.redis.get(self.key)
            if self.token is None:  # first look of this process: adopt (or write) the epoch
                self.token = bytes(value) if value is not None else self._current()
            elif value is None or bytes(value) != self.token:
                self.token = self._current() if value is None else bytes(value)
                self.lost_at = time.monotonic()
                log.error(
                    "broker.restarted_empty: Redis came back without its data (epoch key %s "
                    "gone): queued and running jobs it held are lost",
                    self.key,
                )
            if self.lost_at is not None and time.monotonic() - self.lost_at < REPORT_SECONDS:
                return "restarted-empty"
            return "ok"
