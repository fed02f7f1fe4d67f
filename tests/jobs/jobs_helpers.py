"""Helpers of the job queue tests: wait loops, process checks, a server subprocess."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from service.core.params import SmoothingParams
from service.jobs import JobRecord, LocalQueue
from tests.timing import patience

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
FAKE = "jobs_fakes:scripted"
PARAMS = SmoothingParams(tau=1.0)

if str(HERE) not in sys.path:  # the worker processes import the fake job function from here
    sys.path.insert(0, str(HERE))


def wait_for(predicate: Callable[[], Any], timeout: float = 10.0, interval: float = 0.02) -> Any:
    """Poll ``predicate`` until it returns something truthy; fail the test after ``timeout``
    (a hang guard: stretched by :func:`tests.timing.patience` for a busy machine)."""
    timeout = patience(timeout)
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            pytest.fail(f"condition not met within {timeout:.0f} s")
        time.sleep(interval)


def wait_finished(queue: LocalQueue, job_id: str, timeout: float = 15.0) -> JobRecord:
    """The job's record once it reached a final state."""

    def done() -> JobRecord | None:
        rec = queue.get(job_id)
        return rec if rec is not None and rec.finished else None

    return wait_for(done, timeout)  # type: ignore[no-any-return]


def pid_gone(pid: int) -> bool:
    """Whether a process no longer runs (gone, or a zombie nobody reaped yet)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except FileNotFoundError:
        return True
    except OSError:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        return False
    return stat.rsplit(")", 1)[1].split()[0] in ("Z", "X")


def server_env() -> dict[str, str]:
    """Environment for a server subprocess that can import the fakes."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(HERE), str(REPO), env.get("PYTHONPATH", "")])
    return env


def start_server(data_dir: Path, **options: Any) -> subprocess.Popen[bytes]:
    """Run ``jobs_server.py`` (a LocalQueue in its own process) on ``data_dir``."""
    args = [sys.executable, str(HERE / "jobs_server.py"), str(data_dir)]
    for key, value in options.items():
        args += [f"--{key.replace('_', '-')}", str(value)]
    return subprocess.Popen(args, env=server_env(), cwd=REPO)
