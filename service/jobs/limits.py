"""Resource limits of a job: the per-job memory limit and its enforcement.

* **Admission** (:func:`check_admission`): before a job is accepted its peak memory and its time
  are estimated by the engine (``service.core.linalg.resources.estimate_resources``, dimension
  and codimension included); above the per-job memory limit or the job time limit the job is
  refused with :class:`~service.jobs.errors.JobTooLarge` (422, estimates and limits stated).
* **Enforcement** (:func:`limit_memory`): every job process runs under ``RLIMIT_AS`` = its
  address space when the job starts + the per-job limit. An estimate that was wrong makes that one
  job fail with ``out-of-memory`` (``MemoryError``) instead of the machine swapping or the OOM
  killer picking a random process. ``RLIMIT_AS`` needs no privileges and works in any container
  (cgroups would need a delegated hierarchy); it counts address space, not resident memory, so
  the limit is generous by what allocators reserve but do not touch.
* **Threads**: BLAS/OpenMP threads per job process come from the engine's thread budget
  (``service.core.linalg.threads``), applied once in the process that forks the job processes.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import os
import resource
import signal
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from service.workflows import admission
from service.workflows.admission import (  # the admission's tiles decision, named here too
    HALO_FACTOR,
    MIN_TILE_POINTS,
    PARENT_BYTES_PER_POINT,
    auto_tile_points,
)

if TYPE_CHECKING:
    from service.core.params import SmoothingParams
    from service.workflows.admission import JobSize

__all__ = [
    "HALO_FACTOR",
    "MIN_TILE_POINTS",
    "PARENT_BYTES_PER_POINT",
    "auto_tile_points",
    "check_admission",
    "default_job_memory",
    "limit_memory",
    "memory_cap_hit",
    "set_parent_death_signal",
    "tile_workers",
]

_GIB = 1024**3
_PR_SET_PDEATHSIG = 1


def physical_memory() -> int:
    """Bytes of RAM of this machine (or of the container's cgroup limit, if lower)."""
    total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    for path in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            text = Path(path).read_text().strip()
        except OSError:
            continue
        if text.isdigit():
            total = min(total, int(text))
    return int(total)


def default_job_memory(workers: int) -> int:
    """Per-job memory limit when none is configured: 80 % of the RAM shared by ``workers`` jobs.

    At least 256 MiB.
    """
    return max(256 * 1024**2, int(0.8 * physical_memory() / max(1, workers)))


def _job_time_limit() -> float | None:
    """The job time limit of this process's settings (``GEOSMOOTH_JOB_TIMEOUT``), if valid."""
    from service.settings import ConfigError, get_settings

    try:
        return float(get_settings().job_timeout)
    except ConfigError:
        return None


def check_admission(
    size: JobSize, params: SmoothingParams, limit: int | None, time_limit: float | None = None
) -> None:
    """:func:`service.workflows.admission.check_admission` with the job time limit of the
    settings by default (at which the job would be stopped anyway).

    Raises
    ------
    JobTooLarge
        With the estimates and the limits (bytes, GiB and seconds in the message).
    """
    time_limit = _job_time_limit() if time_limit is None else time_limit
    admission.check_admission(size, params, limit, time_limit)


_MAP_FAILURES = ("failed to map segment", "cannot allocate memory", "out of memory")


def memory_cap_hit(exc: BaseException) -> bool:
    """Whether ``exc`` is the address-space cap being hit: a ``MemoryError``, or a library that
    could not be loaded (``dlopen``: "failed to map segment from shared object") or mapped
    (``ENOMEM``) under it; such a job failed for its memory, not for an internal error."""
    seen: set[int] = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        if isinstance(exc, MemoryError):
            return True
        if isinstance(exc, OSError) and exc.errno == errno.ENOMEM:
            return True
        if isinstance(exc, ImportError | OSError):
            text = str(exc).lower()
            if any(marker in text for marker in _MAP_FAILURES):
                return True
        exc = exc.__cause__ or exc.__context__  # type: ignore[assignment]
    return False


def _address_space() -> int:
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmSize:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


def limit_memory(limit: int | None) -> int | None:
    """Cap this process's address space at its current size + ``limit`` bytes.

    Returns the cap set (``None`` when ``limit`` is ``None`` or the platform has no
    ``RLIMIT_AS``). Never raises the hard limit; never lowers below what is mapped already.
    """
    if limit is None or not hasattr(resource, "RLIMIT_AS"):
        return None
    cap = _address_space() + int(limit)
    _soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    if hard != resource.RLIM_INFINITY:
        cap = min(cap, hard)
    resource.setrlimit(resource.RLIMIT_AS, (cap, hard))
    return cap


# --- tiled jobs (issue 23): the tile size admission chooses -----------------------------


def tile_workers() -> int:
    """Tile processes of this job: its thread share (``OMP_NUM_THREADS``, set by the worker
    from ``threads_per_worker``), at least 1."""
    try:
        return max(1, int(os.environ.get("OMP_NUM_THREADS", "1")))
    except ValueError:
        return 1


def set_parent_death_signal(sig: int = signal.SIGKILL) -> bool:
    """Ask Linux to send ``sig`` to this process when its parent dies; ``False`` elsewhere."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(_PR_SET_PDEATHSIG, int(sig), 0, 0, 0) == 0
    except (OSError, AttributeError):  # pragma: no cover - non-glibc oddities
        return False


def reap_zombies(keep: int | None = None) -> list[int]:
    """Reap this process's children that exited and nobody waited for (zombies), except
    ``keep`` (a child someone else waits for, e.g. RQ's work horse); their pids (Linux)."""
    me = os.getpid()
    reaped: list[int] = []
    try:
        entries = os.listdir("/proc")
    except OSError:
        return reaped
    for name in entries:
        if not name.isdigit() or int(name) == keep:
            continue
        try:
            with open(f"/proc/{name}/stat", encoding="ascii", errors="replace") as fh:
                fields = fh.read().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue
        if len(fields) > 1 and fields[0] == "Z" and fields[1] == str(me):
            with contextlib.suppress(ChildProcessError, OSError):
                os.waitpid(int(name), os.WNOHANG)
                reaped.append(int(name))
    return reaped
