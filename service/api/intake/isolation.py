"""Run a request's heavy work in its own process: bounded in time and memory, killable.

One process per request (forked from the multiprocessing forkserver the job queue already runs,
which has numpy, scipy and the engine loaded, so a start costs milliseconds). The process

* gets an address-space limit (``RLIMIT_AS`` = what it has mapped at start + a budget), so a
  parse or solve that would need more fails with ``MemoryError`` (413) instead of taking the
  host down;
* is killed when it has used its CPU time (413: too much work for one request; CPU time, not
  wall time, so a busy machine never turns a legal request into a 413: the parent reads the
  child's ``utime + stime`` from ``/proc`` while it waits, and ``RLIMIT_CPU`` in the child is
  the backstop), when its wall-clock safety net (far above the CPU limit) runs out (503 +
  ``Retry-After``: the server is too busy, the request was fine), when the client disconnects
  (``POST /v1/smooth``), and when the server dies (it watches its parent and asks the kernel
  for ``PDEATHSIG``);
* answers one small message (a dict or problem details) through a pipe the event loop waits on
  without blocking, so ``/healthz`` answers while any number of uploads are parsed.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import time
from collections.abc import Callable, Mapping
from typing import Any, TypeVar

import anyio
from starlette.types import Receive

from service.api.errors import ApiProblem
from service.api.http.logs import get_logger
from service.api.intake.worker import child_main

__all__ = ["MIN_WALL_SECONDS", "WALL_FACTOR", "Isolation", "cpu_seconds", "wall_limit"]

#: The wall-clock safety net of a request process, in multiples of its CPU limit ...
WALL_FACTOR = 10.0
#: ... and at least this many seconds.
MIN_WALL_SECONDS = 60.0
#: ``Retry-After`` of a 503 for a server too busy to parse or check an upload now.
RETRY_AFTER_SECONDS = 10
T = TypeVar("T")

log = get_logger("geosmooth.api")


async def _watch_disconnect(receive: Receive, gone: anyio.Event, scope: anyio.CancelScope) -> None:
    while True:
        message = await receive()
        if message["type"] == "http.disconnect":
            gone.set()
            scope.cancel()
            return


def cpu_seconds(pid: int) -> float | None:
    """CPU time (user + system, every thread) process ``pid`` has used; ``None``: unknown."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as fh:
            fields = fh.read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return None


def busy_problem(what: str, wall: float) -> ApiProblem:
    """503 + ``Retry-After``: the server could not finish (or start) the work in time."""
    return ApiProblem(
        503,
        f"the server is too busy to handle this {what} now (waited {wall:g} s; the request is "
        "within its limits); try again later",
        code="server-busy",
        headers={"Retry-After": str(RETRY_AFTER_SECONDS)},
        retry_after=RETRY_AFTER_SECONDS,
    )


def time_problem(what: str, limit: float) -> ApiProblem:
    """413: the work needs more CPU time than one request may use."""
    return ApiProblem(
        413,
        f"{what} did not finish within {limit:g} s of CPU time",
        code=f"{what}-time-limit",
        time_limit_seconds=limit,
    )


class Isolation:
    """Starts request processes (one per call of :meth:`run`).

    Parameters
    ----------
    start_method : str, optional
        ``"forkserver"`` (default on Linux) or ``"spawn"``.
    """

    def __init__(self, start_method: str | None = None) -> None:
        methods = multiprocessing.get_all_start_methods()
        default = "forkserver" if "forkserver" in methods else "spawn"
        self.ctx = multiprocessing.get_context(start_method or default)

    async def run(
        self,
        func: Callable[[Any], T],
        arg: Any,
        *,
        timeout: float,
        memory_bytes: int | None,
        what: str,
        redact: Mapping[str, str] | None = None,
        disconnect: Receive | None = None,
        wall_timeout: float | None = None,
    ) -> T | None:
        """Run ``func(arg)`` in a new process; its answer, or ``None`` if the client left.

        ``timeout`` is CPU seconds; ``wall_timeout`` (default :func:`wall_limit`) the safety
        net in wall-clock seconds.

        Raises
        ------
        ApiProblem
            The function's problem; 413 past ``timeout`` CPU seconds or out of memory; 503 past
            ``wall_timeout``; 500 (logged) for an unexpected exception or crash.
        """
        reader, writer = self.ctx.Pipe(duplex=False)
        proc = self.ctx.Process(  # type: ignore[attr-defined]
            target=child_main,
            args=(writer, func, arg, memory_bytes, dict(redact or {}), timeout),
            daemon=True,
            name=f"geosmooth-{what}",
        )
        gone = anyio.Event()
        watch = _Watch(timeout, wall_timeout or wall_limit(timeout))
        try:
            await anyio.to_thread.run_sync(proc.start)
            writer.close()
            async with anyio.create_task_group() as tg:
                if disconnect is not None:
                    tg.start_soon(_watch_disconnect, disconnect, gone, tg.cancel_scope)
                await watch.wait(reader.fileno(), proc.pid)
                tg.cancel_scope.cancel()
            if gone.is_set():
                log.info("request.abandoned", work=what)
                return None
            if watch.verdict == "cpu":
                raise time_problem(what, timeout)
            if watch.verdict == "wall":
                log.warning("request.wall_limit", work=what, cpu_seconds=watch.cpu,
                            wall_seconds=watch.wall)  # fmt: skip
                raise busy_problem(what, watch.wall)
            return await anyio.to_thread.run_sync(self._answer, reader, proc, what, watch)
        finally:
            reader.close()
            if proc.pid is not None:
                if proc.exitcode is None:
                    proc.kill()
                await anyio.to_thread.run_sync(proc.join, 5.0)

    @staticmethod
    def _answer(reader: Any, proc: Any, what: str, watch: _Watch) -> Any:
        try:
            kind, value, stats = reader.recv()
        except (EOFError, OSError):
            proc.join(5.0)
            cpu_out = proc.exitcode == -signal.SIGKILL and watch.cpu >= watch.cpu_limit
            if proc.exitcode == -signal.SIGXCPU or cpu_out:  # RLIMIT_CPU, the backstop
                raise time_problem(what, watch.cpu_limit) from None
            if proc.exitcode == -signal.SIGKILL:
                raise ApiProblem(
                    413, f"{what} was stopped: it ran out of memory", code="too-large-to-process"
                ) from None
            log.error("request.worker_crashed", work=what, exitcode=proc.exitcode)
            raise ApiProblem(
                500, "An unexpected error occurred; it has been logged.", code="internal"
            ) from None
        mib = 2**20
        log.info(
            "request.worker",
            work=what,
            outcome=kind,
            seconds=round(stats["seconds"], 3),
            cpu_seconds=round(stats.get("cpu_seconds", 0.0), 3),
            rss_start_mib=round(stats["rss_start"] / mib, 1),
            rss_peak_mib=round(stats["rss_peak"] / mib, 1),
        )
        if kind == "ok":
            return value
        if kind == "problem":
            raise ApiProblem.from_wire(value)
        log.error("request.worker_error", work=what, error=value)
        raise ApiProblem(500, "An unexpected error occurred; it has been logged.", code="internal")


def wall_limit(cpu_limit: float) -> float:
    """The wall-clock safety net of a request process: :data:`WALL_FACTOR` times its CPU limit,
    at least :data:`MIN_WALL_SECONDS`."""
    return max(WALL_FACTOR * cpu_limit, MIN_WALL_SECONDS)


class _Watch:
    """Waits for a request process's answer while counting its CPU time and the wall clock."""

    def __init__(self, cpu_limit: float, wall_limit: float) -> None:
        self.cpu_limit, self.wall_limit = cpu_limit, wall_limit
        self.cpu = 0.0
        self.wall = 0.0
        self.verdict: str | None = None  # None: answered (or died); "cpu" / "wall": killed

    async def wait(self, fd: int, pid: int | None) -> None:
        tick = min(0.5, max(0.02, self.cpu_limit / 5))
        started = time.monotonic()
        while True:
            with anyio.move_on_after(tick):
                await anyio.wait_readable(fd)
                return
            self.wall = time.monotonic() - started
            used = cpu_seconds(pid) if pid is not None else None
            if used is not None:
                self.cpu = used
            if self.cpu >= self.cpu_limit:
                self.verdict = "cpu"
                return
            if self.wall >= self.wall_limit:
                self.verdict = "wall"
                return
