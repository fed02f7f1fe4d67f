"""A submitted job's input and parameters tried at submit when the input is small.

A job the engine would refuse (one to three points, identical or collinear points, a LAS file
whose scale makes every point the same, a budget out of range, a noise level that cannot be
estimated ...) is answered 422 with the engine's own typed error instead of 202 and a failed job
a moment later. Rather than a second list of rules that could drift from the engine's, the
engine itself is run on inputs of at most ``submit_dry_run_points`` points (a few ms to a second
in the ingest process, under its time limit; not when the estimate says more than
:data:`DRY_RUN_SECONDS`): exactly what it refuses is refused. Anything else
it raises (a bug, memory) is left to the job, which reports it as usual.
"""

from __future__ import annotations

import warnings
from typing import Any

from service.api.errors import typed_problem

__all__ = ["DRY_RUN_SECONDS", "check_time", "dry_run"]

#: Estimated seconds (one core) above which a small input is not tried at submit.
DRY_RUN_SECONDS = 2.0


def dry_run(geometry: Any, params: Any, max_points: int) -> None:
    """Smooth ``geometry`` with ``params`` when it has at most ``max_points`` points; re-raise
    a typed (4xx) error of the engine, ignore everything else."""
    if max_points <= 0 or len(geometry.points) > max_points:
        return
    from service.core import smooth
    from service.core.linalg.resources import estimate_resources

    n, dim = geometry.points.shape
    faces = None if geometry.faces is None else len(geometry.faces)
    if estimate_resources(n, dim, geometry.kind, params, faces).seconds > DRY_RUN_SECONDS:
        return  # small but expensive (e.g. high codimension): the admission decides

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            smooth(geometry, params)
    except Exception as exc:
        typed = typed_problem(exc)
        if typed is not None and 400 <= typed.status < 500:
            raise


def check_time(geometry: Any, params: Any, time_limit: float | None) -> None:
    """Refuse (422 ``job-too-large``) an input whose estimated time is above ``time_limit``
    *before* the submit's own checks, which cost about as much as the job on such inputs (the
    exact ``phi(0)`` of 50 points in 200-D held the ingest process until its time limit)."""
    if not time_limit:
        return
    from service.jobs.limits import check_admission
    from service.jobs.queue import JobSize

    faces = None if geometry.faces is None else len(geometry.faces)
    n, dim = geometry.points.shape
    size = JobSize(n=n, dim=dim, kind=geometry.kind, n_faces=faces)
    check_admission(size, params, None, time_limit=float(time_limit))
