"""Real components for the RQ backend tests: a redis-server, RQ worker processes, a moto S3 server.

Everything binds 127.0.0.1 on a free port, lives in a temporary directory and is stopped by the
test that started it (processes are ended by pid).
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from service.settings import Settings
from tests.jobs.jobs_helpers import HERE, REPO, wait_for
from tests.timing import load_factor

PYTHON = sys.executable
WEBHOOK_SECRET = "whsec-rq-7d2e"


def free_port() -> int:
    """A free TCP port on the loopback interface."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _ping(port: int) -> bool:
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=0.5) as s:
            s.sendall(b"PING\r\n")
            return s.recv(16).startswith(b"+PONG")
    except OSError:
        return False


@dataclass
class RedisServer:
    """``redis-server`` with an append-only file fsynced on every write (jobs survive a kill)."""

    dir: Path
    port: int = field(default_factory=free_port)
    proc: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        return f"redis://127.0.0.1:{self.port}/0"

    def start(self, retries: int = 3) -> RedisServer:
        self.dir.mkdir(parents=True, exist_ok=True)
        args = ["redis-server", "--port", str(self.port), "--bind", "127.0.0.1", "--dir",
                str(self.dir), "--appendonly", "yes", "--appendfsync", "always", "--save", "",
                "--logfile", str(self.dir / "redis.log")]  # fmt: skip
        self.proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        # ours, not another test's server on a port taken since it was chosen (parallel tests):
        # a redis-server that cannot bind exits
        proc = self.proc
        wait_for(lambda: proc.poll() is not None or _ping(self.port), timeout=15)
        if proc.poll() is not None:
            if retries and "Address already in use" in self._log():
                self.port = free_port()
                return self.start(retries - 1)
            raise RuntimeError(f"redis-server exited with {proc.returncode}: {self._log()}")
        return self

    def _log(self) -> str:
        try:
            return (self.dir / "redis.log").read_text(errors="replace")[-2000:]
        except OSError:
            return ""

    def kill(self) -> None:
        """SIGKILL (no shutdown save: only what the append-only file holds survives)."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL)
            self.proc.wait(10)

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.kill()


def rq_settings(redis_url: str, data_dir: Path, **overrides: Any) -> Settings:
    """Settings of an RQ deployment for tests (short lease and backoff)."""
    values: dict[str, Any] = {
        "queue": "rq",
        "redis_url": redis_url,
        "data_dir": data_dir,
        "rq_queue_name": "geosmooth-test",
        # short, so that a dead worker's job moves on quickly; long enough that a busy machine
        # delaying a heartbeat does not take a live worker for a dead one
        "worker_lease": 4.0 * load_factor(),
        "retry_backoff": 0.2,
        "job_timeout": 30.0,
        "result_ttl": 3600.0,
        "job_memory_limit": 0,
        "workers": 2,
        "threads_per_job": 1,
        "webhook_allow_private": True,
        "webhook_backoff": 0.1,
        "webhook_secret": WEBHOOK_SECRET,
    }
    values.update(overrides)
    return Settings(**values)


def settings_env(settings: Settings) -> dict[str, str]:
    """The environment that gives a subprocess these settings (and the fakes on its path)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("GEOSMOOTH_")}
    for name, value in settings.model_dump(exclude_defaults=True).items():
        if hasattr(value, "get_secret_value"):
            value = value.get_secret_value()
        text = str(value).lower() if isinstance(value, bool) else str(value)
        env[f"GEOSMOOTH_{name.upper()}"] = "" if value is None else text
    env["PYTHONPATH"] = os.pathsep.join([str(HERE), str(REPO), env.get("PYTHONPATH", "")])
    return env


@dataclass
class WorkerProcess:
    """``geosmooth worker`` (``python -m service.cli worker``) with the test runner."""

    settings: Settings
    name: str
    log: Path
    extra_env: dict[str, str] = field(default_factory=dict)
    proc: subprocess.Popen[bytes] | None = None

    def start(self) -> WorkerProcess:
        env = {**settings_env(self.settings), **self.extra_env}
        args = [PYTHON, "-m", "service.cli", "worker", "--name", self.name, "--runner",
                "jobs_fakes:scripted_or_real", "--log-level", "INFO"]  # fmt: skip
        with open(self.log, "ab") as out:
            self.proc = subprocess.Popen(args, env=env, cwd=REPO, stdout=out, stderr=out)
        return self

    @property
    def pid(self) -> int:
        assert self.proc is not None
        return self.proc.pid

    def wait_registered(self, redis: Any, timeout: float = 30.0) -> None:
        """Until RQ lists this worker."""
        from rq import Worker

        wait_for(lambda: any(w.name == self.name for w in Worker.all(connection=redis)),
                 timeout=timeout, interval=0.1)  # fmt: skip

    def kill(self, sig: int = signal.SIGKILL) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(sig)
            self.proc.wait(15)

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(15)
            except subprocess.TimeoutExpired:
                self.kill()


@dataclass
class MotoServer:
    """moto's S3 server (``moto.server``) on a free loopback port."""

    port: int = field(default_factory=free_port)
    proc: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(self) -> MotoServer:
        args = [PYTHON, "-m", "moto.server", "-H", "127.0.0.1", "-p", str(self.port)]
        self.proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

        def up() -> bool:
            try:
                socket.create_connection(("127.0.0.1", self.port), timeout=0.5).close()
                return True
            except OSError:
                return False

        wait_for(up, timeout=30, interval=0.1)
        return self

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            self.proc.wait(10)


def runs(job_dir: Path) -> list[tuple[int, float, float | None]]:
    """``(pid, start, end)`` of every run a fake made of a job (``end`` None: killed)."""
    path = job_dir / "runs"
    out: dict[int, list[Any]] = {}
    order: list[int] = []
    for line in path.read_text().splitlines() if path.exists() else []:
        what, pid, stamp = line.split()
        if what == "start":
            out[int(pid)] = [int(pid), float(stamp), None]
            order.append(int(pid))
        else:
            out[int(pid)][2] = float(stamp)
    return [tuple(out[p]) for p in order]  # type: ignore[misc]

