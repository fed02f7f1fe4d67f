"""Problems recorded on failed jobs.

A problem is a JSON-ready dict with the members of the API's problem details, minus the HTTP
status: ``code``, ``title``, ``detail`` and, when they apply, ``field``, ``indices`` and the
error's own extras (e.g. ``valid_range`` of ``tau-out-of-range``). No traceback ever gets in:
an unexpected exception is reduced to its class name and its message on one line, with absolute
paths replaced by ``<path>`` (an ``OSError`` keeps only its ``strerror``).
"""

from __future__ import annotations

import re
import signal
from typing import Any

from service.jobs.errors import storage_error
from service.workflows.errors import ServiceError

__all__ = [
    "attempts_exhausted",
    "crashed",
    "from_exception",
    "timed_out",
]


_PATH = re.compile(r"(?<![\w.:/])(?:[A-Za-z]:)?(?:[/\\][^\s'\"/\\:,;)]+){2,}[/\\]?")


def _one_line(text: str, limit: int = 300) -> str:
    """One line, at most ``limit`` characters, absolute paths replaced by ``<path>``."""
    line = _PATH.sub("<path>", " ".join(str(text).split()))
    return line if len(line) <= limit else line[: limit - 1] + "…"


def _from_typed(exc: Exception, title: str) -> dict[str, Any]:
    info = dict(exc.to_dict())  # type: ignore[attr-defined]
    out: dict[str, Any] = {
        "code": info.pop("code", "invalid-input"),
        "title": title,
        "detail": _one_line(str(info.pop("message", exc))),
    }
    out.update(info)
    return out


def from_exception(exc: BaseException) -> dict[str, Any]:
    """The problem for an exception raised by a job.

    Core errors (:class:`~service.core.errors.GeosmoothError`) and io format errors keep their
    code, field and indices; anything else becomes ``internal-error`` with one line of detail.
    """
    from service.core.errors import GeosmoothError
    from service.io.errors import FormatError

    if isinstance(exc, GeosmoothError | FormatError | ServiceError):
        return _from_typed(exc, exc.title)
    storage = storage_error(exc)  # a full or read-only disk, an unreachable store
    if storage is not None:
        return _from_typed(storage, storage.title)
    from service.jobs.limits import memory_cap_hit

    if memory_cap_hit(exc):  # also a library that cannot be loaded under the cap
        return {
            "code": "out-of-memory",
            "title": "Out of memory",
            "detail": "The job ran out of memory.",
        }
    message = _one_line(exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc))
    return {
        "code": "internal-error",
        "title": "Internal error",
        "detail": f"{type(exc).__name__}: {message}" if message else type(exc).__name__,
    }


def crashed(exitcode: int | None) -> dict[str, Any]:
    """The problem for a worker process that died without recording an outcome."""
    if exitcode is not None and exitcode < 0:
        try:
            name = signal.Signals(-exitcode).name
        except ValueError:
            name = f"signal {-exitcode}"
        detail = f"The worker process was killed by {name}"
        if -exitcode == signal.SIGKILL:
            detail += " (possibly out of memory)"
    else:
        detail = f"The worker process exited with code {exitcode}"
    return {"code": "worker-crashed", "title": "Worker crashed", "detail": detail + "."}


def timed_out(seconds: float) -> dict[str, Any]:
    """The problem for a job killed at its time limit."""
    return {
        "code": "timeout",
        "title": "Job timed out",
        "detail": f"The job did not finish within {seconds:g} s and was stopped.",
        "timeout": seconds,
    }


def attempts_exhausted(attempts: int, last: str | None = None) -> dict[str, Any]:
    """The problem for a job whose runs were interrupted too often (a poison job).

    ``last``: how the last run ended, when known (e.g. the signal that killed the worker).
    """
    detail = (
        f"The job was interrupted {attempts} times (its server or worker stopped while it"
        " ran) and was given up."
    )
    return {
        "code": "attempts-exhausted",
        "title": "Job interrupted too often",
        "detail": f"{detail} Last run: {last}" if last else detail,
        "attempts": attempts,
    }
