"""The submit check of a job, computed once: estimate, ``tau`` range, dry run, tiles.

``POST /v1/jobs`` enters here through one door, :func:`check_submit`, in its ingest process:

1. the **estimate** of the job's memory and time (``service.core.linalg.resources``): above the
   job time limit it is refused at once (:class:`JobTooLarge`, 422), before the checks below,
   which cost about as much as the job on such inputs (the exact ``phi(0)`` of 50 points in
   200-D held the ingest process until its time limit);
2. the **smoothing factor** against ``(0, phi(0))`` (:mod:`service.core.tau_range`): exact
   when it is affordable, from the centroid bound when the job is tiled or its estimate is
   above the check process's budget (:func:`exact_tau_affordable`);
3. the **dry run**: inputs of at most ``dry_run_points`` points are smoothed once, and what the
   engine refuses (one to three points, identical or collinear points, a LAS file whose scale
   makes every point the same, a noise level that cannot be estimated ...) is answered 422 with
   the engine's own typed error instead of 202 and a failed job a moment later; not when the
   estimate says more than :data:`DRY_RUN_SECONDS`; anything else it raises is left to the job;
4. the **queue's decision** (:func:`decide`) against the queue's memory limit: within the
   limits as it is, tiled (``tile_points`` chosen by :func:`auto_tile_points` when only a tiled
   run fits), or refused. The refusal is recorded, not raised: the queue raises it where it
   always did (after the webhook check, in ``submit``).

The result is an :class:`Admission` that :class:`~service.jobs.queue.NewJob` carries, so the
queue does not estimate again (:func:`service.jobs.admit.admit_size` uses it when it was
decided against the queue's own limits). ``POST /v1/smooth`` checks only what the engine does
not (:func:`check_sync`).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

from service.workflows.errors import ServiceError

if TYPE_CHECKING:
    from service.core.geometry import Geometry
    from service.core.linalg.resources import ResourceEstimate
    from service.core.params import SmoothingParams

__all__ = [
    "DRY_RUN_SECONDS",
    "HALO_FACTOR",
    "MIN_TILE_POINTS",
    "PARENT_BYTES_PER_POINT",
    "Admission",
    "JobSize",
    "JobTooLarge",
    "Policy",
    "auto_tile_points",
    "check_admission",
    "check_submit",
    "check_sync",
    "decide",
    "dry_run",
    "exact_tau_affordable",
]

#: Estimated seconds (one core) above which a small input is not tried at submit.
DRY_RUN_SECONDS = 2.0
#: A tile's points (core + halo) per core point assumed at admission.
HALO_FACTOR = 2.0
#: Bytes per point the job process itself holds in a tiled run (input, output, tile index
#: arrays, a tile being cut): float64 coordinates twice, the mask and index arrays.
PARENT_BYTES_PER_POINT = 160
#: Smallest tile admission chooses (the halo would dominate below).
MIN_TILE_POINTS = 20_000
_GIB = 1024**3


@dataclass(frozen=True)
class JobSize:
    """What the resource estimate of a job needs (known to the API once it parsed the input):
    points ``n``, coordinates per point ``dim``, ``kind`` (``"mesh"``, ``"curve"``, ``"cloud"``)
    and the faces of a mesh."""

    n: int
    dim: int
    kind: str
    n_faces: int | None = None

    @classmethod
    def of(cls, geometry: Geometry) -> JobSize:
        """The size of a parsed geometry."""
        faces = geometry.faces
        return cls(
            n=int(geometry.n),
            dim=int(geometry.dim),
            kind=str(geometry.kind),
            n_faces=None if faces is None else len(faces),
        )


class JobTooLarge(ServiceError):
    """The job's estimated memory or time is above the per-job limit (refused at submit).

    Extras: ``estimate_bytes``, ``estimate_seconds``, ``path``, ``limit_bytes`` or
    ``limit_seconds``.
    """

    code: ClassVar[str] = "job-too-large"
    title: ClassVar[str] = "Job too large"
    status: ClassVar[int] = 422
    exit_code: ClassVar[int] = 2  # see the CLI's table, service/exit_codes.py


@dataclass(frozen=True)
class Policy:
    """What a submit is checked against (the server's settings and the queue's limits)."""

    memory_limit: int | None = None
    time_limit: float | None = None
    exact_tau_max_points: int = 50_000
    dry_run_points: int = 0
    tile_workers: int = 1
    #: The check process's own budget (memory bytes, CPU seconds): above it no operator is built.
    check_memory_bytes: int | None = None
    check_seconds: float | None = None


@dataclass(frozen=True)
class Admission:
    """The submit check's result, carried by :class:`~service.jobs.queue.NewJob`.

    Attributes
    ----------
    size : JobSize
        The parsed input's size.
    params : SmoothingParams
        What the job runs with: ``tile_points`` set when only a tiled run fits.
    limits : tuple
        ``(memory_limit, time_limit, tile_workers)`` it was decided against.
    refusal : dict or None
        :class:`JobTooLarge`'s message and extras when no run fits (raised by :meth:`accepted`).
    """

    size: JobSize
    params: SmoothingParams
    limits: tuple[int | None, float | None, int]
    refusal: dict[str, Any] | None = None

    def accepted(self) -> SmoothingParams:
        """The params to run with; raises the recorded :class:`JobTooLarge`."""
        if self.refusal is not None:
            extra = dict(self.refusal)
            raise JobTooLarge(extra.pop("message"), field="file", **extra)
        return self.params


def _estimate(size: JobSize, params: SmoothingParams, limit: int | None) -> ResourceEstimate:
    from service.core.linalg.resources import estimate_resources

    return estimate_resources(size.n, size.dim, size.kind, params, n_faces=size.n_faces,
                              memory_limit=limit)  # fmt: skip


def _refuse(
    size: JobSize, est: ResourceEstimate, limit: int | None, time_limit: float | None
) -> None:
    """Raise :class:`JobTooLarge` when ``est`` is above ``limit`` bytes or ``time_limit`` s."""
    extras = {
        "estimate_bytes": int(est.memory_bytes),
        "estimate_seconds": float(est.seconds),
        "path": est.path,
    }
    where = f"{size.n} points in {size.dim}-D, {est.path} solver path"
    if limit is not None and est.memory_bytes > limit:
        raise JobTooLarge(
            f"the job needs about {est.memory_bytes / _GIB:.2f} GiB of memory ({where}),"
            f" above the per-job limit of {limit / _GIB:.2f} GiB",
            field="file",
            limit_bytes=int(limit),
            **extras,
        )
    if time_limit is not None and est.seconds > time_limit:
        raise JobTooLarge(
            f"the job needs about {est.seconds:.0f} s ({where}), above the job time limit of"
            f" {time_limit:g} s",
            field="file",
            limit_seconds=float(time_limit),
            **extras,
        )


def check_admission(
    size: JobSize, params: SmoothingParams, limit: int | None, time_limit: float | None
) -> None:
    """Refuse a job whose estimated peak memory is above ``limit`` bytes (``None``: no limit)
    or whose estimated time is above ``time_limit`` seconds (``None``: no limit).

    The estimate counts the dimension and, for normal displacement, the codimension: every
    entry of the system is then a ``codim x codim`` block (50 points in 200-D: 198^2 times the
    entries of the same points in 3-D).

    Raises
    ------
    JobTooLarge
        With the estimates and the limits (bytes, GiB and seconds in the message).
    """
    _refuse(size, _estimate(size, params, limit), limit, time_limit)


def auto_tile_points(
    size: JobSize, params: SmoothingParams, limit: int, workers: int = 1
) -> int | None:
    """The largest ``n / 2^m`` whose tiled run fits ``limit`` bytes (``None``: none does, or
    the parameters have no tiled form)."""
    from service.core.errors import ParameterError
    from service.core.linalg.resources import estimate_resources
    from service.core.tiles import check_tileable

    try:
        check_tileable(params)
    except ParameterError:
        return None
    tile = size.n
    while tile >= 2 * MIN_TILE_POINTS:
        tile = (tile + 1) // 2
        members = min(int(HALO_FACTOR * tile), size.n)
        faces = None if size.n_faces is None else int(size.n_faces * members / size.n)
        est = estimate_resources(members, size.dim, size.kind, params, n_faces=faces,
                                 memory_limit=limit // max(workers, 1))  # fmt: skip
        if PARENT_BYTES_PER_POINT * size.n + workers * est.memory_bytes <= limit:
            return tile
    return None


def decide(
    size: JobSize,
    params: SmoothingParams,
    limit: int | None,
    time_limit: float | None,
    workers: int = 1,
    estimate: ResourceEstimate | None = None,
) -> Admission:
    """The queue's decision: the job as it is, tiled when only a tiled run fits ``limit``
    (:func:`auto_tile_points`), or refused (recorded in the :class:`Admission`).

    ``estimate``: the untiled run's at ``limit``, when the caller has it already.
    """
    limits = (limit, time_limit, workers)
    try:
        _refuse(size, estimate or _estimate(size, params, limit), limit, time_limit)
    except JobTooLarge as exc:
        tile = None
        if not params.tile_points and limit is not None:
            tile = auto_tile_points(size, params, limit, workers)
        if tile is None:
            return Admission(size, params, limits, {"message": exc.message, **exc.extra})
        return Admission(size, params.model_copy(update={"tile_points": tile}), limits)
    return Admission(size, params, limits)


def dry_run(
    geometry: Geometry,
    params: SmoothingParams,
    max_points: int,
    estimate: ResourceEstimate | None = None,
) -> None:
    """Smooth ``geometry`` with ``params`` when it has at most ``max_points`` points and its
    estimate (untiled, no memory limit) is at most :data:`DRY_RUN_SECONDS`; re-raise a typed
    (4xx) error of the engine, ignore everything else."""
    if max_points <= 0 or len(geometry.points) > max_points:
        return
    from service.workflows.smooth_file import run_engine

    est = estimate or _estimate(JobSize.of(geometry), params, None)
    if est.seconds > DRY_RUN_SECONDS:
        return  # small but expensive (e.g. high codimension): the admission decides
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            run_engine(geometry, params)
    except Exception as exc:  # anything but the engine's typed verdict is left to the job
        status = getattr(type(exc), "status", None)  # a typed error: class status, to_dict()
        if not isinstance(status, int) or not callable(getattr(exc, "to_dict", None)):
            return
        if 400 <= status < 500:
            raise


def exact_tau_affordable(
    size: JobSize, est: ResourceEstimate, admission: Admission, policy: Policy
) -> bool:
    """Whether the exact ``phi(0)`` (the input's operator built) fits the submit check: not
    when the job is tiled (it is above the auto-tiling threshold: its operator alone may not fit
    one process) or its estimate is above the check process's own memory or CPU budget."""
    if admission.params.tile_points or admission.refusal is not None:
        return False
    if policy.check_memory_bytes is not None and est.memory_bytes > policy.check_memory_bytes:
        return False
    return policy.check_seconds is None or est.seconds <= policy.check_seconds


def check_submit(geometry: Geometry, params: SmoothingParams, policy: Policy) -> Admission:
    """The submit check of a job (module docstring); the estimate is made once (twice when the
    queue has a memory limit, which changes the solver path it assumes). The queue's decision
    is taken before the ``tau`` check: an input it tiles, or whose estimate is above the check
    process's budget (:func:`exact_tau_affordable`), gets ``tau``/``rms`` checked from its
    counts and coordinates (the centroid bound), never by building its operator, so every input
    the bounds admit is admitted (and tiled) with a ``tau`` as without one.

    Raises
    ------
    JobTooLarge
        Estimated above the job time limit.
    TauOutOfRange
        ``tau`` or ``rms`` outside ``(0, phi(0))``.
    GeosmoothError
        What the engine refuses (the dry run).
    """
    from service.core.tau_range import check_tau

    size = JobSize.of(geometry)
    est = _estimate(size, params, None)
    if policy.time_limit:
        _refuse(size, est, None, float(policy.time_limit))
    same = est if policy.memory_limit is None else None
    admission = decide(
        size, params, policy.memory_limit, policy.time_limit, policy.tile_workers, same
    )
    exact = None if exact_tau_affordable(size, est, admission, policy) else False
    check_tau(geometry, params, policy.exact_tau_max_points, exact=exact)
    if exact is None:
        dry_run(geometry, params, policy.dry_run_points, est)
    return admission


def check_sync(geometry: Geometry, params: SmoothingParams) -> None:
    """``POST /v1/smooth``: only that ``rms`` gives a positive finite ``tau`` (the engine checks
    the range itself; :func:`service.core.tau_range.check_tau` with ``analyse=False``)."""
    from service.core.tau_range import check_tau

    check_tau(geometry, params, 0, analyse=False)
