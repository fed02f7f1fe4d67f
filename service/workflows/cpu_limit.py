"""The CPU seconds one file's run may use (``geosmooth smooth --time-limit``, issue 34 item 5).

The server fails a job after ``job_timeout`` (3600 s); the CLI had no bound, so an input whose
run does not end (an 800,000-point curve whose lambda search cannot converge: ``phi(lambda)``
loses its accuracy at ``lambda / ||M|| ~ 1e-14`` and the search takes every one of its
``max_iterations``) held a core for as long as it ran. The bound is CPU time, not wall time, so
a busy machine never stops a run that would fit (as the server's parse limits, issue 34
item 1).

How: the soft ``RLIMIT_CPU`` of the process is set to the CPU time used so far plus the limit;
the kernel sends ``SIGXCPU`` when it is reached, and the handler raises ``_Stop`` (a
``BaseException``, so no ``except Exception`` of the engine swallows it) in the main thread,
which :func:`cpu_time_limit` turns into the typed :class:`TimeLimitReached` (one line naming
the limit and the option; CLI exit 13). The previous limit and handler are restored on
exit, so each file of a batch gets its own budget. Off the main thread, or where the platform
has no ``RLIMIT_CPU``, no bound is set.
"""

from __future__ import annotations

import contextlib
import math
import resource
import signal
import threading
from collections.abc import Iterator
from types import FrameType
from typing import ClassVar

from service.workflows.errors import ServiceError

__all__ = ["DEFAULT_TIME_LIMIT", "TimeLimitReached", "cpu_time_limit", "parse_time_limit"]

#: CPU seconds of one file's run by default: the server's ``job_timeout`` default
#: (service/settings.py; tests/cli/test_time_limit.py checks that they agree).
DEFAULT_TIME_LIMIT = 3600.0


class TimeLimitReached(ServiceError):
    """The run used its CPU time limit and was stopped; nothing was written.

    Extras: ``limit_seconds``.
    """

    code: ClassVar[str] = "time-limit"
    title: ClassVar[str] = "Time limit reached"
    status: ClassVar[int] = 413
    exit_code: ClassVar[int] = 13  # see the CLI's table, service/exit_codes.py


class _Stop(BaseException):
    """Raised by the ``SIGXCPU`` handler (not an ``Exception``: nothing may swallow it)."""


def parse_time_limit(value: str | None) -> float | None:
    """``--time-limit``: seconds (``None``: the default; ``"none"`` or ``0``: no bound).

    Raises
    ------
    ValueError
        Not a positive number of seconds nor ``none``.
    """
    if value is None:
        return DEFAULT_TIME_LIMIT
    if value.strip().lower() in ("none", "0"):
        return None
    try:
        seconds = float(value)
    except ValueError:
        seconds = math.nan
    if not (math.isfinite(seconds) and seconds > 0):
        raise ValueError(f"expected CPU seconds > 0 or 'none', got {value!r}")
    return seconds


def _raise(_signum: int, _frame: FrameType | None) -> None:
    signal.signal(signal.SIGXCPU, signal.SIG_IGN)  # one stop; later SIGXCPU (1/s) ignored
    raise _Stop


@contextlib.contextmanager
def cpu_time_limit(seconds: float | None) -> Iterator[None]:
    """Run the block with at most ``seconds`` more CPU seconds (``None``: no bound).

    Raises
    ------
    TimeLimitReached
        Naming the limit and the option that raises it.
    """
    bound = getattr(resource, "RLIMIT_CPU", None)
    main = threading.current_thread() is threading.main_thread()
    if seconds is None or bound is None or not main:
        yield
        return
    soft, hard = resource.getrlimit(bound)
    used = resource.getrusage(resource.RUSAGE_SELF)
    start = used.ru_utime + used.ru_stime
    wanted = math.ceil(start + seconds)
    if hard != resource.RLIM_INFINITY:
        wanted = min(wanted, hard - 1)  # the hard limit kills (SIGKILL): stop before it
    if soft != resource.RLIM_INFINITY and soft <= wanted:
        yield  # a stricter limit is already set (ulimit -t): it applies as it is
        return
    previous = signal.signal(signal.SIGXCPU, _raise)
    resource.setrlimit(bound, (wanted, hard))
    try:
        yield
    except _Stop:
        raise TimeLimitReached(
            f"the run used its CPU time limit of {seconds:g} s and was stopped, nothing written"
            " (--time-limit SECONDS raises it; 'none': no bound)",
            limit_seconds=seconds,
        ) from None
    finally:
        resource.setrlimit(bound, (soft, hard))
        signal.signal(signal.SIGXCPU, previous)
