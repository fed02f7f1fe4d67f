"""Thread budget of the numerical libraries (issue 8: N workers on N cores must not
oversubscribe).

numpy/scipy bundle OpenBLAS, CHOLMOD links the system OpenBLAS and OpenMP (libgomp); each sizes
its pool to all cores by default, so ``N`` worker processes on ``N`` cores would run ``N^2``
threads. A worker calls :func:`limit_threads` once at start with its share of the cores
(:func:`threads_per_worker`). The CLI and the library facade (``geosmooth``) call
:func:`use_default_threads` once: one thread unless ``GEOSMOOTH_THREADS`` says otherwise
(``all`` or a positive integer). Measured (164K icosphere, direct path, one process, 2 cores
under load 8-14 plus a 2-process CPU burner, medians of 3): 1 thread 54.6 s wall (9.9 s CPU),
2 threads 224 s wall (12.6 s CPU): OpenMP/OpenBLAS pools that spin for a busy core lose 4x,
so more threads are only a win on a machine known to be idle (docs/threads.md). The engine
itself reads no environment: callers pass the numbers (settings ``workers`` and the CPU count).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any

__all__ = [
    "THREADS_ENV",
    "default_threads",
    "limit_threads",
    "thread_counts",
    "threads_per_worker",
    "use_default_threads",
]

_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
#: The one variable that sets the thread count of the CLI and the library (docs/threads.md).
THREADS_ENV = "GEOSMOOTH_THREADS"
_applied: list[int] = []


def _cores() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def default_threads(value: str | None, cores: int | None = None) -> int:
    """Threads from the value of ``GEOSMOOTH_THREADS``: unset or empty -> 1, ``all`` -> the
    usable cores, else a positive integer.

    Raises
    ------
    ValueError
        Any other value (the message names the variable).
    """
    text = (value or "").strip().lower()
    if not text:
        return 1
    if text == "all":
        return _cores() if cores is None else cores
    if text.isdigit() and int(text) > 0:
        return int(text)
    raise ValueError(f"{THREADS_ENV} must be 'all' or a positive integer, got {value!r}")


def use_default_threads(environ: Mapping[str, str]) -> int:
    """Apply :func:`default_threads` of ``environ`` once per process (later calls keep it)."""
    if not _applied:
        _applied.append(default_threads(environ.get(THREADS_ENV)))
        limit_threads(_applied[0], load=False)  # libraries loaded later read the variables
    return _applied[0]


def threads_per_worker(workers: int, cores: int | None = None) -> int:
    """``max(1, cores // workers)`` with ``cores`` the CPUs this process may use."""
    if cores is None:
        cores = _cores()
    return max(1, cores // max(workers, 1))


def limit_threads(threads: int, load: bool = True) -> Any:
    """Cap every loaded BLAS/OpenMP pool (numpy's, scipy's, CHOLMOD's) at ``threads``.

    With ``load``, loads the engine's libraries first (threadpoolctl only sees loaded ones);
    either way it sets the usual variables, which libraries loaded later (OpenBLAS, libgomp read
    them when they load) and child processes follow. Returns the ``threadpoolctl`` limiter (keep
    it to restore, or drop it: the limits stay).
    """
    from threadpoolctl import threadpool_limits

    if load:
        import numpy  # noqa: F401
        import scipy.sparse.linalg  # noqa: F401

        from service.core.linalg import solver  # noqa: F401  (CHOLMOD and its BLAS / OpenMP)

    for name in _ENV:
        os.environ[name] = str(threads)
    return threadpool_limits(limits=threads)


def thread_counts() -> dict[str, int]:
    """Threads per loaded library (``internal_api`` -> largest pool), for diagnostics."""
    from threadpoolctl import threadpool_info

    out: dict[str, int] = {}
    for info in threadpool_info():
        key = info["internal_api"]
        out[key] = max(out.get(key, 0), int(info["num_threads"]))
    return out
