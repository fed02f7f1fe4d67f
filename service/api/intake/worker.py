"""The entry point of a request process (see :mod:`service.api.intake.isolation`).

Kept light (no web framework, no logging setup): the process imports this module, the function
it runs (:mod:`service.api.intake.ingest`, :mod:`service.api.intake.smoothing`) and nothing else
beyond what the forkserver preloaded.
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

from service.api.errors import ApiProblem, typed_problem
from service.jobs.errors import storage_error

__all__ = ["child_main"]

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
        typed = typed_problem(storage_error(exc) or exc)
        if typed is not None:
            return "problem", typed.to_wire()
        return "internal", f"{type(exc).__name__}: {' '.join(str(exc).split())[:300]}"


def _limit_cpu(seconds: float) -> None:
    """``RLIMIT_CPU``, the backstop of the parent's CPU count: SIGXCPU a little after the limit
    (the parent kills the process at the limit itself), SIGKILL a little after that."""
    soft = int(seconds) + 2
    _, hard = resource.getrlimit(resource.RLIMIT_CPU)
    want = soft + 5
    resource.setrlimit(resource.RLIMIT_CPU, (soft, want if hard < 0 else min(want, hard)))


def _one_thread() -> None:
    """One BLAS/OpenMP thread in a request process (inherited pools have the jobs' count): a
    parse or check gains nothing from more, and an idle pool thread spinning for work on a busy
    machine was CPU time counted against the request's limit (~10 ms)."""
    with contextlib.suppress(Exception):
        from threadpoolctl import threadpool_limits

        threadpool_limits(limits=1)


def child_main(
    conn: Any,
    func: Callable[[Any], Any],
    arg: Any,
    budget: int | None,
    redact: Mapping[str, str],
    cpu_limit: float | None = None,
) -> None:
    _arm_child()
    _one_thread()
    rss_start, started = _status("VmRSS"), time.perf_counter()
    if budget:
        with contextlib.suppress(OSError, ValueError):
            _limit_memory(budget)
    if cpu_limit:
        with contextlib.suppress(OSError, ValueError):
            _limit_cpu(cpu_limit)
    kind, value = _outcome(func, arg, budget)
    if kind == "problem":
        value = _redact(value, redact)
    stats = {
        "seconds": time.perf_counter() - started,
        "cpu_seconds": time.process_time(),
        "rss_start": rss_start,
        "rss_peak": _status("VmHWM"),
    }
    conn.send((kind, value, stats))
    conn.close()
