"""A throwaway Redis + RQ workers deployment on loopback for the queue benchmark."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from service.settings import Settings

REPO = Path(__file__).resolve().parents[2]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Cluster:
    """redis-server (AOF, fsync always, as in docker-compose.yml) and ``n`` worker processes."""

    def __init__(self, root: Path, workers: int, queue_name: str) -> None:
        self.root = root
        self.port = free_port()
        self.settings = Settings(
            queue="rq", redis_url=f"redis://127.0.0.1:{self.port}/0",
            data_dir=root / "data", rq_queue_name=queue_name, job_memory_limit=0,
            workers=workers, threads_per_job=1, worker_lease=15.0,
        )  # fmt: skip
        self.n = workers
        self.redis: subprocess.Popen[bytes] | None = None
        self.procs: list[subprocess.Popen[bytes]] = []

    def env(self) -> dict[str, str]:
        env = {k: v for k, v in os.environ.items() if not k.startswith("GEOSMOOTH_")}
        for name, value in self.settings.model_dump(exclude_defaults=True).items():
            env[f"GEOSMOOTH_{name.upper()}"] = str(value)
        env["PYTHONPATH"] = str(REPO)
        return env

    def start(self) -> Cluster:
        self.root.mkdir(parents=True, exist_ok=True)
        self.redis = subprocess.Popen(
            ["redis-server", "--port", str(self.port), "--bind", "127.0.0.1", "--dir",
             str(self.root), "--appendonly", "yes", "--appendfsync", "always", "--save", ""],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )  # fmt: skip
        self._wait(lambda: self._ping())
        log = open(self.root / "workers.log", "ab")  # noqa: SIM115 - closed with the processes
        for i in range(self.n):
            args = [sys.executable, "-m", "service.jobs.distributed.worker", "--name", f"bench{i}",
                    "--log-level", "WARNING"]  # fmt: skip
            self.procs.append(subprocess.Popen(args, env=self.env(), cwd=REPO, stdout=log,
                                               stderr=log))  # fmt: skip
        from redis import Redis
        from rq import Worker

        redis = Redis.from_url(self.settings.redis_url)
        self._wait(lambda: len(Worker.all(connection=redis)) == self.n, 60)
        return self

    def redis_pid(self) -> int:
        assert self.redis is not None
        return self.redis.pid

    def _ping(self) -> bool:
        try:
            with socket.create_connection(("127.0.0.1", self.port), timeout=0.5) as s:
                s.sendall(b"PING\r\n")
                return s.recv(16).startswith(b"+PONG")
        except OSError:
            return False

    @staticmethod
    def _wait(predicate: Any, timeout: float = 20.0) -> None:
        deadline = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() > deadline:
                raise RuntimeError("benchmark cluster did not come up")
            time.sleep(0.05)

    def stop(self) -> None:
        for p in self.procs:
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
        for p in self.procs:
            try:
                p.wait(20)
            except subprocess.TimeoutExpired:
                p.kill()
        if self.redis is not None and self.redis.poll() is None:
            self.redis.terminate()
            self.redis.wait(10)
