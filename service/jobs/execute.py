"""One run of a job function: the part both backends' job processes share.

The embedded queue's job process (:mod:`service.jobs.embedded.child`) and the RQ work horse
(:mod:`service.jobs.distributed.tasks`) each claim their run and record its outcome in their
own store, and cap their address space (:func:`service.jobs.limits.limit_memory`) at their own
moment; in between they do the same thing, written here once: build the
:class:`~service.jobs.runner.JobContext` from the job's record, run the job function, flush the
progress held back, and write ``report.json``.
"""

from __future__ import annotations

import importlib
import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from service.core.params import SmoothingParams  # imported before any RLIMIT_AS cap
from service.jobs.runner import DEFAULT_RUNNER, JobContext

if TYPE_CHECKING:
    from service.jobs.queue import JobRecord
    from service.jobs.tiles import TileMap

__all__ = ["JobFunction", "RunOptions", "load_runner", "run_function", "write_report"]

#: A job function: a :class:`JobContext` in, the report dict out.
JobFunction = Callable[[JobContext], dict[str, Any]]


@dataclass(frozen=True)
class RunOptions:
    """What a run of a job function gets from the backend that runs it.

    Attributes
    ----------
    runner : str
        The job function, ``"package.module:function"``.
    memory_limit : int or None
        The per-job memory limit (bytes) the job function plans with; the caller caps the
        process at it.
    progress_interval : float
        Minimum seconds between two progress writes within one stage.
    tiles : TileMap or None
        What runs a tiled job's tiles (``None``: local processes).
    """

    runner: str = DEFAULT_RUNNER
    memory_limit: int | None = None
    progress_interval: float = 0.2
    tiles: TileMap | None = None


def load_runner(path: str) -> JobFunction:
    """Import a job function from ``"package.module:function"``."""
    module_name, _, attr = path.partition(":")
    if not attr:
        raise ValueError(f"runner must look like 'module:function', got {path!r}")
    fn = getattr(importlib.import_module(module_name), attr)
    if not callable(fn):
        raise TypeError(f"runner {path!r} is not callable")
    return fn  # type: ignore[no-any-return]


def run_function(
    rec: JobRecord,
    job_dir: Path,
    input_path: Path,
    report_progress: Callable[[dict[str, Any]], bool],
    options: RunOptions,
) -> tuple[JobContext, dict[str, Any]]:
    """Run the job function on ``rec`` in ``job_dir``, then flush the progress held back.

    Returns the context (its ``written`` files) and the report. ``RunLost`` and the job's own
    errors propagate: the caller records them in its store.
    """
    ctx = JobContext(
        job_id=rec.id,
        job_dir=job_dir,
        input_path=input_path,
        fmt=rec.fmt,
        params=SmoothingParams.model_validate(rec.params),
        report_progress=report_progress,
        progress_interval=options.progress_interval,
        weld=rec.weld,
        memory_limit=options.memory_limit,
        tiles=options.tiles,
    )
    report = load_runner(options.runner)(ctx)
    ctx.flush_progress()
    return ctx, report


def write_report(ctx: JobContext, report: dict[str, Any]) -> None:
    """Store the report as the job's ``report.json`` (durable, atomic)."""
    ctx.write("report.json", json.dumps(report, indent=1, allow_nan=False).encode())
