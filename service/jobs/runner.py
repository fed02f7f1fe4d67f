"""What one job does, inside its worker process: read, smooth, write.

A *job function* takes a :class:`JobContext` and returns the report dict; the worker process
(:mod:`service.jobs.child`) records the outcome. :func:`smooth_job` is the real one;
``LocalQueue(runner="module:function")`` swaps in another (tests use fakes).
"""

from __future__ import annotations

import io
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from service.jobs.files import write_durable

if TYPE_CHECKING:
    from service.core.params import SmoothingParams
    from service.core.progress import ProgressEvent

__all__ = ["DEFAULT_RUNNER", "JobContext", "RunLost", "smooth_job"]

DEFAULT_RUNNER = "service.jobs.runner:smooth_job"


class RunLost(BaseException):
    """The run no longer holds its job (cancelled, timed out or taken over): stop quietly.

    A ``BaseException`` so that a job function's ``except Exception`` cannot swallow it.
    """


@dataclass
class JobContext:
    """Everything a job function may use.

    Attributes
    ----------
    job_id : str
        The job.
    job_dir : Path
        Its directory (input and outputs).
    input_path : Path
        The stored input file.
    fmt : str
        Its format.
    params : SmoothingParams
        Smoothing parameters.
    report_progress : callable
        ``(iteration, lam, phi, tau, relative_error) -> bool`` writing to the job's row;
        ``False`` when the run lost its job.
    progress_interval : float
        Minimum seconds between two progress writes (the first and last always go through).
    options : dict
        How to read the input (``{"weld": True}``), from the job's ``options.json``.
    """

    job_id: str
    job_dir: Path
    input_path: Path
    fmt: str
    params: SmoothingParams
    report_progress: Callable[[int, float, float, float | None, float | None], bool]
    progress_interval: float = 0.2
    options: dict[str, Any] = field(default_factory=dict)
    _last_write: float = field(default=float("-inf"), repr=False)
    _pending: ProgressEvent | None = field(default=None, repr=False)

    def progress(self, event: ProgressEvent) -> None:
        """Progress callback for :func:`service.core.smooth` (throttled).

        The engine's events carry the resolved ``tau``; events before the first lambda carry
        no ``lam``/``phi`` and are not recorded.

        Raises
        ------
        RunLost
            When the job was cancelled or taken away from this run.
        """
        if event.lam is None or event.phi is None:
            return
        now = time.monotonic()
        if now - self._last_write < self.progress_interval:
            self._pending = event
            return
        self._last_write = now
        self._pending = None
        ok = self.report_progress(
            event.iteration, event.lam, event.phi, event.tau, event.relative_error
        )
        if not ok:
            raise RunLost(self.job_id)

    def flush_progress(self) -> None:
        """Write a progress update held back by throttling."""
        if self._pending is not None:
            self._last_write = float("-inf")
            self.progress(self._pending)

    def write(self, name: str, data: bytes) -> Path:
        """Write an output file into the job directory durably and atomically."""
        path = self.job_dir / name
        write_durable(path, data)
        return path


def smooth_job(ctx: JobContext) -> dict[str, Any]:
    """The real job: read the input, smooth it, store ``result.npy`` and ``result.<fmt>``.

    Parameters
    ----------
    ctx : JobContext
        The run.

    Returns
    -------
    dict
        ``SmoothResult.report()``.
    """
    from service.core.pipeline import smooth
    from service.io import read_geometry, write_geometry

    weld = bool(ctx.options.get("weld", False))
    doc = read_geometry(ctx.input_path, ctx.fmt, weld=weld)
    result = smooth(doc.geometry, ctx.params, progress=ctx.progress)
    ctx.flush_progress()
    buf = io.BytesIO()
    np.save(buf, np.ascontiguousarray(result.points, dtype=np.float64))
    ctx.write("result.npy", buf.getvalue())
    ctx.write(f"result.{ctx.fmt}", write_geometry(doc, ctx.fmt, result.points))
    return result.report()
