"""Thread budget of the numerical libraries (service/core/linalg/threads.py)."""

from __future__ import annotations

import subprocess
import sys

from service.core.linalg.threads import threads_per_worker


def test_threads_per_worker_shares_the_cores() -> None:
    assert threads_per_worker(1, 8) == 8
    assert threads_per_worker(2, 8) == 4
    assert threads_per_worker(8, 8) == 1
    assert threads_per_worker(16, 8) == 1
    assert threads_per_worker(0, 4) == 4


def test_limit_threads_caps_blas_openmp_and_cholmod_pools() -> None:
    """In a fresh interpreter (limits are process-wide): every pool, CHOLMOD's OpenBLAS and
    OpenMP included, runs one thread after the call, and smoothing still works."""
    code = (
        "from service.core.linalg.threads import limit_threads, thread_counts\n"
        "limit_threads(1)\n"
        "counts = thread_counts()\n"
        "assert counts and set(counts.values()) == {1}, counts\n"
        "assert {'openblas', 'openmp'} <= set(counts), counts\n"
        "import numpy as np, trimesh\n"
        "from service.core import Geometry, SmoothingParams, smooth\n"
        "m = trimesh.creation.icosphere(2)\n"
        "r = smooth(Geometry(m.vertices * 1.01, faces=m.faces), SmoothingParams(lam=0.1))\n"
        "assert np.isfinite(r.points).all()\n"
        "print('ok')\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "ok"
