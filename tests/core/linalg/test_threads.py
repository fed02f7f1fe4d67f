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


def test_default_threads_reads_one_variable() -> None:
    import pytest

    from service.core.linalg.threads import default_threads

    assert default_threads(None) == 1 and default_threads("") == 1
    assert default_threads("3") == 3
    assert default_threads("all", cores=6) == 6
    for bad in ("0", "-2", "two", "1.5"):
        with pytest.raises(ValueError, match="GEOSMOOTH_THREADS"):
            default_threads(bad)


def test_cli_applies_the_thread_default_and_rejects_bad_values(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """`geosmooth info` runs with one thread by default, N with GEOSMOOTH_THREADS=N; a bad
    value is a usage error (exit 2) naming the variable."""
    import os

    import numpy as np

    points = np.random.default_rng(0).normal(size=(200, 3))
    src = tmp_path / "c.xyz"
    np.savetxt(src, points)
    probe = (
        "import sys\n"
        "from service.cli import main\n"
        "from service.core.linalg.threads import thread_counts\n"
        "code = main(['info', sys.argv[1], '--compact'])\n"
        "print(max(thread_counts().values()), code, file=sys.stderr)\n"
    )
    for value, want in (("", "1 0"), ("2", "2 0")):
        env = {**os.environ, "GEOSMOOTH_THREADS": value}
        done = subprocess.run([sys.executable, "-c", probe, str(src)], env=env,
                              capture_output=True, text=True, check=False)  # fmt: skip
        assert done.stderr.strip().splitlines()[-1] == want, done.stderr
    env = {**os.environ, "GEOSMOOTH_THREADS": "lots"}
    done = subprocess.run([sys.executable, "-m", "service.cli", "info", str(src)], env=env,
                          capture_output=True, text=True, check=False)  # fmt: skip
    assert done.returncode == 2 and "GEOSMOOTH_THREADS" in done.stderr
