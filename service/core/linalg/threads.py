"""Thread budget of the numerical libraries (issue 8: N workers on N cores must not
oversubscribe).

numpy/scipy bundle OpenBLAS, CHOLMOD links the system OpenBLAS and OpenMP (libgomp); each sizes
its pool to all cores by default, so ``N`` worker processes on ``N`` cores would run ``N^2``
threads. A worker calls :func:`limit_threads` once at start with its share of the cores
(:func:`threads_per_worker`); the CLI and a single API process keep all cores. The engine
itself reads no environment: callers pass the numbers (settings ``workers`` and the CPU count).
"""

from __future__ import annotations

import os
from typing import Any

__all__ = ["limit_threads", "thread_counts", "threads_per_worker"]

_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def threads_per_worker(workers: int, cores: int | None = None) -> int:
    """``max(1, cores // workers)`` with ``cores`` the CPUs this process may use."""
    if cores is None:
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else 1
    return max(1, cores // max(workers, 1))


def limit_threads(threads: int) -> Any:
    """Cap every loaded BLAS/OpenMP pool (numpy's, scipy's, CHOLMOD's) at ``threads``.

    Loads the engine's libraries first (threadpoolctl only sees loaded ones) and also sets the
    usual variables for libraries loaded later and for child processes. Returns the
    ``threadpoolctl`` limiter (keep it to restore, or drop it: the limits stay).
    """
    import numpy  # noqa: F401
    import scipy.sparse.linalg  # noqa: F401
    from threadpoolctl import threadpool_limits

    from service.core.linalg import solver  # noqa: F401  (loads CHOLMOD and its BLAS / OpenMP)

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
