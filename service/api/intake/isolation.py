"""Run a request's heavy work in its own process: bounded in time and memory, killable.

One process per request (forked from the multiprocessing forkserver the job queue already runs,
which has numpy, scipy and the engine loaded, so a start costs milliseconds). The process

* gets an address-space limit (``RLIMIT_AS`` = what it has mapped at start + a budget), so a
  parse or solve that would need more fails with ``MemoryError`` (413) instead of taking the
  host down;
* is killed at its deadline (413: too much work for one request), when the client disconnects
  (``POST /v1/smooth``), and when the server dies (it watches its parent and asks the kernel
  for ``PDEATHSIG``);
* answers one small message (a dict or problem details) through a pipe the event loop waits on
  without blocking, so ``/healthz`` answers while any number of uploads are parsed.
"""

from __future__ import annotations

import multiprocessing
import signal
from collections.abc import Callable, Mapping
from typing import Any, TypeVar

import anyio
from starlette.types import Receive

from service.api.errors import ApiProblem
from service.api.http.logs import get_logger
from service.api.intake.worker import child_main

__all__ = ["Isolation"]
T = TypeVar("T")

log = get_logger("geosmooth.api")


async def _watch_disconnect(receive: Receive, gone: anyio.Event, scope: anyio.CancelScope) -> None:
    while True:
        message = await receive()
        if message["type"] == "http.disconnect":
            gone.set()
            scope.cancel()
            return


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
    ) -> T | None:
        """Run ``func(arg)`` in a new process; its answer, or ``None`` if the client left.

        Raises
        ------
        ApiProblem
            The function's problem; 413 past ``timeout`` or out of memory; 500 (logged) for an
            unexpected exception or crash.
        """
        reader, writer = self.ctx.Pipe(duplex=False)
        proc = self.ctx.Process(  # type: ignore[attr-defined]
            target=child_main,
            args=(writer, func, arg, memory_bytes, dict(redact or {})),
            daemon=True,
            name=f"geosmooth-{what}",
        )
        gone = anyio.Event()
        try:
            await anyio.to_thread.run_sync(proc.start)
            writer.close()
            with anyio.move_on_after(timeout) as deadline:
                async with anyio.create_task_group() as tg:
                    if disconnect is not None:
                        tg.start_soon(_watch_disconnect, disconnect, gone, tg.cancel_scope)
                    await anyio.wait_readable(reader.fileno())
                    tg.cancel_scope.cancel()
            if gone.is_set():
                log.info("request.abandoned", work=what)
                return None
            if deadline.cancelled_caught:
                raise ApiProblem(
                    413,
                    f"{what} did not finish within {timeout:g} s",
                    code=f"{what}-time-limit",
                    time_limit_seconds=timeout,
                )
            return await anyio.to_thread.run_sync(self._answer, reader, proc, what)
        finally:
            reader.close()
            if proc.pid is not None:
                if proc.exitcode is None:
                    proc.kill()
                await anyio.to_thread.run_sync(proc.join, 5.0)

    @staticmethod
    def _answer(reader: Any, proc: Any, what: str) -> Any:
        try:
            kind, value, stats = reader.recv()
        except (EOFError, OSError):
            proc.join(5.0)
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
            rss_start_mib=round(stats["rss_start"] / mib, 1),
            rss_peak_mib=round(stats["rss_peak"] / mib, 1),
        )
        if kind == "ok":
            return value
        if kind == "problem":
            raise ApiProblem.from_wire(value)
        log.error("request.worker_error", work=what, error=value)
        raise ApiProblem(500, "An unexpected error occurred; it has been logged.", code="internal")
