"""Structured logs: one JSON object per line (or readable text), via structlog.

:func:`configure_logging` routes structlog *and* the standard library's loggers (uvicorn, the job
queue's ``geosmooth.jobs``) through the same processors, so every line has ``timestamp``,
``level``, ``logger`` and ``event``, plus the context bound for the current request
(``request_id``, ``tenant``) and whatever the caller passed (``job_id``, ``status`` ...; for the
standard library via ``extra={...}``).

Event names of the service: ``request`` (one per HTTP request: method, path, status,
duration_ms), ``request.error`` (an unexpected exception, with its traceback),
``request.abandoned`` (the client left during ``POST /v1/smooth``), ``job.submitted``,
``job.cancelled``, ``job.deleted`` (API side); the queue logs ``job.started``,
``job.progress``, ``job.succeeded``, ``job.failed``, ``job.cancelled`` and ``job.requeued``
with the same ``job_id`` key.
"""

from __future__ import annotations

import json
import logging
import sys
from typing import Any

import structlog

from service.api.errors import finite

__all__ = ["configure_logging", "get_logger"]

_LEVELS = {
    "debug": logging.DEBUG,
    "info": logging.INFO,
    "warning": logging.WARNING,
    "error": logging.ERROR,
}


class _CurrentStderr(logging.StreamHandler):  # type: ignore[type-arg]
    """A handler that writes to ``sys.stderr`` *as it is when a record is emitted*.

    ``StreamHandler(sys.stderr)`` keeps the stream object it was given: when that object is
    replaced and closed (pytest's output capture, a daemon reattaching its streams), every later
    record from a background thread (queue sweeper, webhook deliveries) failed with
    "--- Logging error --- ValueError: I/O operation on closed file" and a traceback.
    """

    def __init__(self) -> None:
        super().__init__(sys.stderr)

    @property  # type: ignore[override]
    def stream(self) -> Any:
        return sys.stderr

    @stream.setter
    def stream(self, value: Any) -> None:  # StreamHandler.__init__ assigns it
        pass


def _shared_processors(*, foreign: bool) -> list[Any]:
    extra = [structlog.stdlib.ExtraAdder()] if foreign else []  # stdlib's extra={...}
    return [
        structlog.contextvars.merge_contextvars,
        structlog.stdlib.add_log_level,
        structlog.stdlib.add_logger_name,
        *extra,
        structlog.processors.TimeStamper(fmt="iso", utc=True),
    ]


def configure_logging(level: str = "info", fmt: str = "json") -> None:
    """Configure structlog and the standard library's root logger (idempotent).

    Parameters
    ----------
    level : {"debug", "info", "warning", "error"}
        Lowest level written.
    fmt : {"json", "console"}
        One JSON object per line, or aligned text for a terminal.
    """
    renderer: Any = (
        structlog.processors.JSONRenderer(serializer=_dumps)
        if fmt == "json"
        else structlog.dev.ConsoleRenderer(colors=False)
    )
    final = [structlog.processors.format_exc_info, renderer] if fmt == "json" else [renderer]
    structlog.configure(
        processors=[
            *_shared_processors(foreign=False),
            structlog.stdlib.ProcessorFormatter.wrap_for_formatter,
        ],
        logger_factory=structlog.stdlib.LoggerFactory(),
        wrapper_class=structlog.stdlib.BoundLogger,
        cache_logger_on_first_use=True,
    )
    formatter = structlog.stdlib.ProcessorFormatter(
        foreign_pre_chain=_shared_processors(foreign=True),
        processors=[structlog.stdlib.ProcessorFormatter.remove_processors_meta, *final],
    )
    handler = _CurrentStderr()
    handler.setFormatter(formatter)
    root = logging.getLogger()
    root.handlers = [handler]
    root.setLevel(_LEVELS.get(level, logging.INFO))
    for name in ("uvicorn", "uvicorn.error", "uvicorn.access"):
        logger = logging.getLogger(name)
        logger.handlers = []
        logger.propagate = True
    # one line per request comes from RequestContextMiddleware; uvicorn's would duplicate it
    logging.getLogger("uvicorn.access").disabled = True


def _dumps(obj: Any, **kw: Any) -> str:
    try:
        return json.dumps(obj, allow_nan=False, default=str)
    except ValueError:
        return json.dumps(finite(obj), default=str)


def _pass_to_stdlib() -> None:
    """Until :func:`configure_logging` runs (library use, tests): hand events to ``logging``."""
    structlog.configure(
        processors=[
            structlog.contextvars.merge_contextvars,
            structlog.stdlib.render_to_log_kwargs,
        ],
        logger_factory=structlog.stdlib.LoggerFactory(),
        wrapper_class=structlog.stdlib.BoundLogger,
        cache_logger_on_first_use=False,
    )


if not structlog.is_configured():
    _pass_to_stdlib()


def get_logger(name: str = "geosmooth.api") -> Any:
    """A structlog logger (``log.info("event", key=value)``)."""
    return structlog.get_logger(name)

