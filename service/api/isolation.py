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

import contextlib
import ctypes
import json
import multiprocessing
import multiprocessing.connection
import os
import resource
import signal
import sys
import threading
import time
from collections.abc import Callable, Mapping
from typing import Any

import anyio
from starlette.types import Receive

from service.api.errors import ApiProblem, typed_problem
from service.api.logs import get_logger

__all__ = ["Isolation"]

log = get_logger("geosmooth.api")
_PR_SET_PDEATHSIG = 1


def _arm_child() -> None:
    """Die with the server (forkserver children: the forkserver is the OS parent)."""
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            ctypes.CDLL(None).prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
    with contextlib.suppress(AttributeError, OSError):  # let the forkserver exit with us
        from multiprocessing import forkserver

        server = forkserver._forkserver  # type: ignore[attr-defined]
        fd = getattr(server, "_forkserver_alive_fd", None)
        if fd is not None:
            os.close(fd)
            setattr(server, "_forkserver_alive_fd", None)  # noqa: B010 (private attribute)
    parent = multiprocessing.parent_process()
    if parent is not None and parent.sentinel is not None:
        sentinel = parent.sentinel

        def watch() -> None:
            multiprocessing.connection.wait([sentinel])
            os.kill(os.getpid(), signal.SIGKILL)

        threading.Thread(target=watch, daemon=True).start()


def _status(field: str) -> int:
    """A ``/proc/self/status`` size in bytes (``VmSize``, ``VmRSS``, ``VmHWM``); 0 if unknown."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            return next(int(ln.split()[1]) * 1024 for ln in fh if ln.startswith(field + ":"))
    except (OSError, StopIteration, ValueError):
        return 0


def _limit_memory(budget: int) -> None:
    vm = _status("VmSize")
    _, hard = resource.getrlimit(resource.RLIMIT_AS)
    soft = vm + budget
    resource.setrlimit(resource.RLIMIT_AS, (soft if hard < 0 else min(soft, hard), hard))


def _redact(wire: dict[str, Any], redact: Mapping[str, str]) -> dict[str, Any]:
    text = json.dumps(wire)
    for secret, shown in sorted(redact.items(), key=lambda kv: -len(kv[0])):
        text = text.replace(secret, shown)
    return json.loads(text)  # type: ignore[no-any-return]


def _outcome(func: Callable[[Any], Any], arg: Any, budget: int | None) -> tuple[str, Any]:
    try:
        return "ok", func(arg)
    except ApiProblem as raised:
        return "problem", raised.to_wire()
    except MemoryError:
        mib = f" ({budget // 2**20} MiB)" if budget else ""
        problem = ApiProblem(
            413,
            f"the request needs more memory than one request may use{mib}",
            code="too-large-to-process",
            memory_limit_bytes=budget,
        )
        return "problem", problem.to_wire()
    except BaseException as exc:
        typed = typed_problem(exc)
        if typed is not None:
            return "problem", typed.to_wire()
        return "internal", f"{type(exc).__name__}: {' '.join(str(exc).split())[:300]}"


def _child_main(
    conn: Any, func: Callable[[Any], Any], arg: Any, budget: int | None, redact: Mapping[str, str]
) -> None:
    _arm_child()
    rss_start, started = _status("VmRSS"), time.perf_counter()
    if budget:
        with contextlib.suppress(OSError, ValueError):
            _limit_memory(budget)
    kind, value = _outcome(func, arg, budget)
    if kind == "problem":
        value = _redact(value, redact)
    stats = {
        "seconds": time.perf_counter() - started,
        "rss_start": rss_start,
        "rss_peak": _status("VmHWM"),
    }
    conn.send((kind, value, stats))
    conn.close()


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
        func: Callable[[Any], dict[str, Any]],
        arg: Any,
        *,
        timeout: float,
        memory_bytes: int | None,
        what: str,
        redact: Mapping[str, str] | None = None,
        disconnect: Receive | None = None,
    ) -> dict[str, Any] | None:
        """Run ``func(arg)`` in a new process; its dict, or ``None`` if the client left.

        Raises
        ------
        ApiProblem
            The function's problem; 413 past ``timeout`` or out of memory; 500 (logged) for an
            unexpected exception or crash.
        """
        reader, writer = self.ctx.Pipe(duplex=False)
        proc = self.ctx.Process(  # type: ignore[attr-defined]
            target=_child_main,
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
    def _answer(reader: Any, proc: Any, what: str) -> dict[str, Any]:
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
            return value  # type: ignore[no-any-return]
        if kind == "problem":
            raise ApiProblem.from_wire(value)
        log.error("request.worker_error", work=what, error=value)
        raise ApiProblem(500, "An unexpected error occurred; it has been logged.", code="internal")
