"""Restart safety: a server process killed with SIGKILL loses no job and leaves no orphan."""

from __future__ import annotations

import signal
import subprocess
from collections.abc import Callable
from pathlib import Path

from service.jobs import JobStatus, LocalQueue
from service.jobs.queue import NewJob
from tests.jobs.jobs_fakes import script
from tests.jobs.jobs_helpers import PARAMS, pid_gone, start_server, wait_finished, wait_for
from tests.timing import patience

MakeQueue = Callable[..., LocalQueue]


def _pids(queue: LocalQueue, job_id: str) -> list[int]:
    path = queue.files.dir(job_id) / "pids"
    return [int(x) for x in path.read_text().split()] if path.exists() else []


def _ppid(pid: int) -> int:
    return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])


def _kill(server: subprocess.Popen[bytes]) -> None:
    server.send_signal(signal.SIGKILL)
    server.wait(10)


def test_sigkill_of_the_server_loses_no_job(make_queue: MakeQueue, tmp_path: Path) -> None:
    data_dir = tmp_path / "data"
    # submit through a queue that is not started: the jobs only live in the store
    client = make_queue(start=False, data_dir=data_dir)
    ids = [
        client.submit(NewJob.check(script("sleep", seconds=2.0, steps=8), "json", PARAMS)).id
        for _ in range(4)
    ]
    server = start_server(data_dir, workers=2)
    try:

        def two_running() -> list[str] | None:
            running = [
                j
                for j in ids
                if (r := client.get(j)) and r.status is JobStatus.RUNNING and _pids(client, j)
            ]
            return running if len(running) >= 2 else None

        running = wait_for(two_running, timeout=20)
        children = [pid for j in running for pid in _pids(client, j)]
        parents = {_ppid(pid) for pid in children}  # the server's forkserver
        _kill(server)
    finally:
        if server.poll() is None:
            _kill(server)
    # the job processes die with their server (PR_SET_PDEATHSIG): no orphan keeps running
    wait_for(lambda: all(pid_gone(p) for p in children), timeout=5)
    assert server.pid not in parents
    wait_for(lambda: all(pid_gone(p) for p in parents), timeout=5)  # the forkserver too
    states = {j: client.get(j).status for j in ids}  # type: ignore[union-attr]
    assert list(states.values()).count(JobStatus.RUNNING) == 2
    assert list(states.values()).count(JobStatus.QUEUED) == 2

    queue = make_queue(data_dir=data_dir)  # the restarted server
    records = {j: wait_finished(queue, j, timeout=20) for j in ids}
    assert all(r.status is JobStatus.SUCCEEDED for r in records.values())
    for job_id in running:  # interrupted runs: retried once, the first process is gone
        assert records[job_id].attempts == 2
        first, second = _pids(queue, job_id)
        assert first in children and second not in children
    for job_id in set(ids) - set(running):
        assert records[job_id].attempts == 1 and len(_pids(queue, job_id)) == 1


def test_poison_job_gives_up_after_max_attempts(make_queue: MakeQueue, tmp_path: Path) -> None:
    data_dir = tmp_path / "data"
    client = make_queue(start=False, data_dir=data_dir, max_attempts=2)
    poison = client.submit(NewJob.check(script("kill_server"), "json", PARAMS)).id
    for attempt in range(1, 3):
        server = start_server(data_dir, workers=1, max_attempts=2)
        try:
            assert server.wait(patience(30)) == -signal.SIGKILL  # the job killed its server
        finally:
            if server.poll() is None:
                _kill(server)
        rec = client.get(poison)
        assert rec is not None and rec.status is JobStatus.RUNNING and rec.attempts == attempt
    wait_for(lambda: all(pid_gone(p) for p in _pids(client, poison)), timeout=5)
    assert len(_pids(client, poison)) == 2

    queue = make_queue(data_dir=data_dir, max_attempts=2)  # recovery gives up on it
    rec = queue.get(poison)
    assert rec is not None and rec.status is JobStatus.FAILED and rec.attempts == 2
    assert rec.problem is not None and rec.problem["code"] == "attempts-exhausted"
    assert "2 times" in rec.problem["detail"]
    # and the queue goes on
    ok = queue.submit(NewJob.check(script("ok"), "json", PARAMS)).id
    assert wait_finished(queue, ok).status is JobStatus.SUCCEEDED
    assert len(_pids(queue, poison)) == 2  # never started again
