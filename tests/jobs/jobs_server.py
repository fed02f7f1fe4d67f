"""A job server in its own process, for the hard-stop tests: ``python jobs_server.py DATA_DIR``.

Writes its pid to ``DATA_DIR/server.pid``, starts a :class:`LocalQueue` and runs until killed.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path


def main() -> None:
    """Parse the options, start the queue, wait forever."""
    from service.jobs.config import LocalConfig
    from service.jobs.embedded.queue import LocalQueue

    ap = argparse.ArgumentParser()
    ap.add_argument("data_dir", type=Path)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--runner", default="jobs_fakes:scripted")
    ap.add_argument("--max-attempts", type=int, default=3)
    ap.add_argument("--poll-interval", type=float, default=0.1)
    ap.add_argument("--retry-backoff", type=float, default=0.2)
    ns = ap.parse_args()
    ns.data_dir.mkdir(parents=True, exist_ok=True)
    (ns.data_dir / "server.pid").write_text(str(os.getpid()))
    queue = LocalQueue(LocalConfig(
        ns.data_dir,
        workers=ns.workers,
        job_timeout=60.0,
        result_ttl=3600.0,
        runner=ns.runner,
        max_attempts=ns.max_attempts,
        poll_interval=ns.poll_interval,
        progress_interval=0.05,
        retry_backoff=ns.retry_backoff,
    ))
    queue.start()
    (ns.data_dir / "server.ready").write_text(str(os.getpid()))
    while True:
        time.sleep(1.0)


if __name__ == "__main__":
    main()
