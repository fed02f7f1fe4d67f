"""Webhook delivery in the background of the process that finished a job.

One delivery per job at a time (claimed in the job store, so two processes never both deliver;
a claim older than :data:`STALE_CLAIM` seconds, whose deliverer died, is taken over by the next
sweep). Deliveries run on a few daemon threads, since one may retry for minutes.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from service.jobs.webhooks import deliver

if TYPE_CHECKING:
    from service.settings import Settings

__all__ = ["STALE_CLAIM", "Notifier"]

log = logging.getLogger("geosmooth.jobs")

#: Seconds after which an unfinished delivery claim is presumed dead (longer than any retry run).
STALE_CLAIM = 900.0
_THREADS = 4


class Notifier:
    """Delivers webhooks of finished jobs.

    Parameters
    ----------
    settings : Settings or None
        Secret, SSRF policy, timeouts and retries (``None``: from the environment).
    payload : callable
        ``job_id -> (url, body dict) | None``.
    claim : callable
        ``(job_id, stale_after) -> bool``: take the delivery (``False``: someone else has it).
    mark : callable
        ``(job_id, "delivered" | "failed")``.
    """

    def __init__(
        self,
        settings: Settings | None,
        payload: Callable[[str], tuple[str, dict[str, Any]] | None],
        claim: Callable[[str, float], bool],
        mark: Callable[[str, str], None],
    ) -> None:
        self._settings = settings
        self._payload = payload
        self._claim = claim
        self._mark = mark
        self._queue: queue.Queue[str | None] = queue.Queue()
        self._threads: list[threading.Thread] = []
        self._pending: set[str] = set()
        self._lock = threading.Lock()
        self._stopping = threading.Event()

    def start(self) -> None:
        """Start the delivery threads."""
        if self._settings is None:
            from service.settings import get_settings

            self._settings = get_settings()
        self._stopping.clear()
        self._threads = [
            threading.Thread(target=self._loop, name=f"geosmooth-webhook-{i}", daemon=True)
            for i in range(_THREADS)
        ]
        for t in self._threads:
            t.start()

    def stop(self) -> None:
        """Stop delivering: retries are abandoned (their claim goes stale and the next sweep of
        any server redoes them); waits for a POST in flight (at most ``webhook_timeout``)."""
        self._stopping.set()
        for _ in self._threads:
            self._queue.put(None)
        timeout = self._settings.webhook_timeout + 1.0 if self._settings else 1.0
        deadline = time.monotonic() + timeout
        for t in self._threads:
            t.join(max(0.0, deadline - time.monotonic()))
        self._threads = []

    def enqueue(self, job_id: str) -> None:
        """Deliver the webhook of a finished job (no-op if it is already waiting here)."""
        with self._lock:
            if job_id in self._pending:
                return
            self._pending.add(job_id)
        self._queue.put(job_id)

    def _loop(self) -> None:
        while (job_id := self._queue.get()) is not None:
            try:
                self._deliver(job_id)
            except Exception:
                log.exception("webhook of job %s failed", job_id)
            finally:
                with self._lock:
                    self._pending.discard(job_id)

    def _deliver(self, job_id: str) -> None:
        assert self._settings is not None
        if not self._claim(job_id, STALE_CLAIM):
            return
        found = self._payload(job_id)
        if found is None:
            return
        url, body = found
        ok, tries = deliver(url, body, self._settings, stop=self._stopping)
        if self._stopping.is_set() and not ok:
            return  # interrupted: left to the next sweep
        self._mark(job_id, "delivered" if ok else "failed")
        log.info("webhook of job %s %s after %d tries", job_id,
                 "delivered" if ok else "given up", tries)  # fmt: skip
