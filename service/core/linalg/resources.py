"""Memory and time of a smoothing run: estimated before it runs, and the path it takes.

Two estimates:

* :func:`estimate_resources` from the sizes alone (``n``, dimension, kind, parameters), for
  admission control at submit time (jobs, HTTP): a model calibrated on the benchmark of
  ``benchmarks/speed`` (see ``benchmarks/quality/README.md``).
* :func:`factor_size` from the symbolic analysis of the actual matrix (elimination tree and
  column counts of the Cholesky factor under the fill-reducing ordering), before any numeric
  factorization; :func:`choose_solver` uses it to take the matrix-free path when the factor
  would not fit the memory budget.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import scipy.sparse as sp

from service.core.linalg.solver import Gram, cholmod_available
from service.core.params import SmoothingParams
from service.core.params.rules import codimension_of, displacement_mode
from service.core.warnings import EngineWarning, warning

__all__ = [
    "MATRIX_FREE_FROM",
    "ResourceEstimate",
    "choose_solver",
    "estimate_resources",
    "factor_size",
    "prefer_matrix_free",
]

Path = Literal["direct", "matrix-free"]
_BYTES_PER_FACTOR_ENTRY = 8 * 1.25  # value plus supernodal padding (measured 1.1-1.3)


@dataclass(frozen=True)
class ResourceEstimate:
    """Predicted peak memory (bytes), seconds on one core, and the solver path."""

    memory_bytes: int
    seconds: float
    path: Path


def _neighbours(kind: str, params: SmoothingParams | None) -> tuple[float, int]:
    """Entries per row of L and the k of the cloud's neighbour query (0 for meshes/curves)."""
    if kind == "mesh":
        return 7.0, 0
    if kind == "curve":
        return 3.0, 0
    k = params.k if params is not None else 12
    delaunay = params is None or params.neighborhood == "delaunay"
    return (7.0 if delaunay else k + 1.0), k


def _normal_unknowns(n: int, dim: int, kind: str, params: SmoothingParams | None) -> int:
    """Unknowns per point of the system: the codimension with normal displacement, else 1
    (free displacement solves for the ``dim`` coordinates as right-hand sides of one matrix).

    As the plan decides (:func:`service.core.params.rules.displacement_mode`, the one rule).
    """
    mode = "auto" if params is None else params.displacement
    run = (params.method, params.tau_rule) if params is not None else ("tikhonov", "auto")
    if displacement_mode(mode, kind, dim, *run) != "normal":
        return 1
    return max(codimension_of(kind, dim), 1)


def _build_bytes(n: int, dim: int, kind: str, params: SmoothingParams | None, faces: int) -> float:
    """Input and output points, neighbourhood build temporaries, weights and L (three copies:
    L, L_F and its transpose), per the measurements in service/core/README.md."""
    nnz_row, k = _neighbours(kind, params)
    out = 8.0 * n * dim * 6 + 72.0 * faces + 36.0 * n * nnz_row + 32.0 * n * nnz_row
    if kind == "mesh":
        out += 400.0 * n  # wedges, adjacency keys
    elif kind == "cloud":
        delaunay = params is None or params.neighborhood == "delaunay"
        out += 8.0 * n * (k + 1) * ((dim + 2) * 4 if delaunay else 3)
    return out


def estimate_resources(
    n: int,
    dim: int,
    kind: str,
    params: SmoothingParams | None = None,
    n_faces: int | None = None,
    *,
    memory_limit: int | None = None,
) -> ResourceEstimate:
    """Peak memory, time (one core) and path of smoothing ``n`` points of dimension ``dim``.

    A model calibrated on measurements (service/core/README.md): peak RSS of ``geosmooth
    smooth`` was within 10 % of it for a 1M-vertex mesh and a 1M-point cloud (CG path) and a
    200K-point cloud with k = 64; a safety factor of 1.3 is applied. The direct path adds
    ``L^T L`` and the Cholesky factor (METIS fill ~ 10.5 n log2 n entries on meshes).

    Parameters
    ----------
    n, dim : int
    kind : {"mesh", "curve", "cloud"}
    params : SmoothingParams, optional
    n_faces : int, optional
        Triangles (meshes); default ``2 n``.
    memory_limit : int, optional
        With ``solver="auto"`` the path is matrix-free when the direct path would not fit
        (as :func:`choose_solver` decides from the symbolic analysis at run time).

    Returns
    -------
    ResourceEstimate
    """
    nnz_row, k = _neighbours(kind, params)
    faces = n_faces if n_faces is not None else (2 * n if kind == "mesh" else 0)
    build = _build_bytes(n, dim, kind, params, faces)
    nnz_m = n * min(nnz_row**2, 3.0 * nnz_row**1.5, float(n))
    log_n = max(math.log2(max(n, 2)), 1.0)
    entries = 5.0 * n if kind == "curve" else (10.5 if kind == "mesh" else 14.0) * n * log_n
    entries = min(entries, n * (n + 1) / 2.0)  # a factor is at most dense
    # Normal displacement: r unknowns per point, every entry an r x r block (eq. of
    # displacement.projected_normal_system), built from an einsum over the dim coordinates.
    r = _normal_unknowns(n, dim, kind, params)
    blocks = r * r
    build += 3 * 8.0 * n * nnz_row * blocks if r > 1 else 0.0
    nnz_m *= blocks
    entries *= blocks
    direct = build + 36.0 * nnz_m + entries * _BYTES_PER_FACTOR_ENTRY + 8.0 * n * dim * 8
    matfree = build + 8.0 * n * dim * 12 + (36.0 * nnz_m if r > 1 else 0.0)
    solver = params.solver if params is not None else "auto"
    dense = nnz_m > DENSE_ROWS * n
    too_big = memory_limit is not None and 1.3 * direct > memory_limit
    path: Path = (
        "matrix-free" if solver == "cg" or (solver == "auto" and (dense or too_big)) else "direct"
    )
    flops_build = n * (60.0 * nnz_row + (400.0 * (k + 1) if kind == "cloud" else 0.0))
    flops_build += n * nnz_row * dim * blocks * (4.0 if r > 1 else 0.0)  # blocks N_i^T N_j
    unknowns = n * r
    if path == "direct":
        work = 2.5 * entries**2 / unknowns / 3e9 + 4 * 12.0 * entries * dim / 1e9
    else:
        work = 250 * 4.0 * n * nnz_row * dim * r / 5e8  # ~250 products with L_F^T L_F
    seconds = flops_build / 1e8 + work
    mem = direct if path == "direct" else matfree
    return ResourceEstimate(int(1.3 * mem), float(seconds), path)


def factor_size(pattern: sp.spmatrix, perm: np.ndarray | None) -> tuple[int, float]:
    """Entries and flops of the Cholesky factor of ``pattern[perm][:, perm]`` (symbolic).

    Elimination tree (Liu) and the row subtrees give the column counts exactly, in time
    proportional to the factor's entries (compiled with numba).

    Returns
    -------
    entries : int
    flops : float
        ``sum_j c_j^2`` over the column counts ``c_j``.
    """
    A = sp.csr_matrix(pattern)
    if perm is not None:
        A = A[perm][:, perm]
    A = sp.tril(A, k=-1, format="csr")
    A.sort_indices()
    counts = _colcounts(A.shape[0], A.indptr.astype(np.int64), A.indices.astype(np.int64))
    c = counts.astype(np.float64)
    return int(counts.sum()), float(np.sum(c * c))


def _colcounts(n: int, indptr: np.ndarray, indices: np.ndarray) -> np.ndarray:
    from service.core.linalg.symbolic import colcounts

    return colcounts(n, indptr, indices)


#: Entries per row of ``L^T L`` (its upper bound) above which ``auto`` never forms it: k-NN
#: neighbourhoods with k = 64 give ~4000 (meshes ~50, Delaunay neighbourhoods ~50-80).
DENSE_ROWS = 400
#: Unknowns from which ``solver="auto"`` takes conjugate gradients when lambda is not small.
MATRIX_FREE_FROM = 200_000
#: ... and ``lambda >= MATRIX_FREE_MIN_LAMBDA * ||M_t||`` (condition number at most 1e3).
MATRIX_FREE_MIN_LAMBDA = 1e-3


def prefer_matrix_free(size: int, lam: float, mu_bound: float) -> bool:
    """Whether CG beats a factorization for ``size`` unknowns at ``lambda`` (the estimate).

    CG needs O(sqrt(||M_t|| / lambda)) products whatever ``n`` (issue 8: ~100 at lambda* ~ 0.05),
    while the factorization grows like ``n^1.5``; measured crossover in service/core/README.md.
    """
    return size >= MATRIX_FREE_FROM and lam >= MATRIX_FREE_MIN_LAMBDA * mu_bound


def choose_solver(
    system: Any,
    params: SmoothingParams,
    memory_limit: int | None,
    warn: Callable[[EngineWarning], None],
) -> Literal["cholmod", "superlu", "cg"]:
    """The solver of a run: the named one, or for ``"auto"`` CHOLMOD unless it would not fit
    (then ``warn`` is told why: a ``"matrix-free"`` warning).

    With a ``memory_limit``, the factor's size is counted from the symbolic analysis of
    ``K = M + D^2`` (AMD ordering) when the coarse model says it might not fit.
    """
    if params.solver != "auto":
        return params.solver
    name: Literal["cholmod", "superlu"] = "cholmod"  # falls back to SuperLU with a warning
    m = system.size
    M = system.M
    nnz_m = M.nnz_bound() if isinstance(M, Gram) else M.nnz
    if m >= 2000 and nnz_m > DENSE_ROWS * m:
        warn(warning(
            "matrix-free",
            f"matrix-free path: L^T L would have about {nnz_m / m:.0f} entries per row "
            f"(more than {DENSE_ROWS}); its factor would be far larger",
            entries_per_row=nnz_m / m, bound=DENSE_ROWS,
        ))  # fmt: skip
        return "cg"
    if memory_limit is None or m < 2000:
        return name
    m_bytes = 12.0 * nnz_m * 3  # M, K's pattern and values, the analysis' copy
    coarse = 0.5 * nnz_m * max(math.log2(m), 1.0) * _BYTES_PER_FACTOR_ENTRY + m_bytes
    if coarse < memory_limit / 8:
        return name
    if m_bytes > memory_limit / 2:
        warn(warning(
            "matrix-free",
            f"matrix-free path: L^T L alone would take {m_bytes / 2**20:.0f} MiB, more than "
            f"half the memory limit of {memory_limit / 2**20:.0f} MiB",
            bytes=m_bytes, memory_limit=memory_limit,
        ))  # fmt: skip
        return "cg"
    from service.core.linalg import cache

    pattern = (sp.csc_matrix(system.explicit()) + sp.diags(system.d2)).tocsc()
    perm = cache.analysis_of(pattern).P() if cholmod_available() else None
    entries, _ = factor_size(pattern, perm)
    need = entries * _BYTES_PER_FACTOR_ENTRY
    if need > memory_limit / 2:
        warn(warning(
            "matrix-free",
            f"matrix-free path: the Cholesky factor would take {need / 2**20:.0f} MiB, more "
            f"than half the memory limit of {memory_limit / 2**20:.0f} MiB",
            bytes=need, memory_limit=memory_limit,
        ))  # fmt: skip
        return "cg"
    return name
