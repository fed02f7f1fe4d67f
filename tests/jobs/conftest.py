"""Fixtures of the job queue tests: started queues with a scripted fake job function."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from service.jobs.config import LocalConfig
from service.jobs.embedded.queue import LocalQueue
from tests.jobs.jobs_helpers import FAKE


@pytest.fixture
def make_queue(tmp_path: Path) -> Iterator[Callable[..., LocalQueue]]:
    """Factory of started queues on ``tmp_path`` (fake job function by default); stopped after."""
    made: list[LocalQueue] = []

    def make(start: bool = True, **options: Any) -> LocalQueue:
        kw: dict[str, Any] = {
            "workers": 2,
            "job_timeout": 30.0,
            "result_ttl": 3600.0,
            "runner": FAKE,
            "poll_interval": 0.1,
            "kill_grace": 1.0,
            "lease": 5.0,
            "progress_interval": 0.05,
            "retry_backoff": 0.2,
        }
        kw.update(options)
        queue = LocalQueue(LocalConfig(kw.pop("data_dir", tmp_path / "data"), **kw))
        made.append(queue)
        if start:
            queue.start()
        return queue

    yield make
    for queue in made:
        queue.stop()
