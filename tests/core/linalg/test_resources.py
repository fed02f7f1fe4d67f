"""estimate_resources(), the symbolic factor size and the memory-based path choice."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from service.core import Geometry, SmoothingParams, smooth
from service.core.linalg.resources import estimate_resources, factor_size
from tests.core.core_fixtures import noisy_icosphere


def test_factor_size_is_exact_against_cholmod() -> None:
    from sksparse import cholmod

    A = sp.random(300, 300, 0.02, random_state=1)
    A = (A @ A.T + sp.eye(300) * 10).tocsc()
    f = cholmod.analyze(A, mode="simplicial", ordering_method="amd")
    f.cholesky_inplace(A)
    entries, flops = factor_size(A, f.P())
    assert entries == f.L().nnz
    counts = np.diff(f.L().tocsc().indptr)
    assert flops == pytest.approx(float(np.sum(counts.astype(float) ** 2)))


def test_estimate_grows_and_switches_path_under_a_limit() -> None:
    small = estimate_resources(10_000, 3, "mesh", SmoothingParams(tau=1.0))
    big = estimate_resources(1_000_000, 3, "mesh", SmoothingParams(tau=1.0))
    assert small.path == big.path == "direct"
    assert big.memory_bytes > 50 * small.memory_bytes
    assert big.seconds > small.seconds > 0
    limited = estimate_resources(
        1_000_000, 3, "mesh", SmoothingParams(tau=1.0), memory_limit=big.memory_bytes // 2
    )
    assert limited.path == "matrix-free" and limited.memory_bytes < big.memory_bytes
    cg = estimate_resources(1_000, 3, "cloud", SmoothingParams(tau=1.0, solver="cg"))
    assert cg.path == "matrix-free"


def test_small_memory_limit_selects_the_matrix_free_path() -> None:
    P, F = noisy_icosphere(4, 0.01)  # 2562 vertices
    g = Geometry(P, faces=F)
    direct = smooth(g, SmoothingParams(rms=0.005))
    low = smooth(g, SmoothingParams(rms=0.005), memory_limit=64 * 1024)
    assert direct.solver == "cholmod" and low.solver == "cg"
    assert low.factorizations == 0 and low.matvecs > 0
    assert any(w.code == "matrix-free" for w in low.warnings)
    assert low.relative_error <= 1e-3
    roomy = smooth(g, SmoothingParams(rms=0.005), memory_limit=2**34)
    assert roomy.solver == "cholmod"
