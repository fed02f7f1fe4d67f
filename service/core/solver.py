"""Our thin wrapper over the sparse solvers for the normal equations of report eq. (17).

For the free points ``F`` (fixed points ``C`` have infinite weight and are eliminated, report
section 8) the system is::

    (L_F^T L_F + lambda D_F^2) X_F = lambda D_F^2 P_F - L_F^T L_C P_C

where ``L_F`` / ``L_C`` are the free / fixed columns of the rows of ``L`` belonging to free
points. With CHOLMOD (scikit-sparse) the symbolic analysis is done once; every lambda is one
numeric refactorization plus one solve of all ``s`` columns together. SciPy's SuperLU is the
fallback, selectable by name and used automatically (with a warning) when scikit-sparse cannot
be imported. Nothing outside this module touches the scikit-sparse API (it changed in 0.5).
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray

from service.core.errors import SolverError

__all__ = ["NormalEquations", "SolverStats", "cholmod_available", "split_fixed"]

try:  # pragma: no cover - depends on the machine
    from sksparse import cholmod as _cholmod

    _CHOLMOD_IMPORT_ERROR: str | None = None
except ImportError as exc:  # pragma: no cover - depends on the machine
    _cholmod = None
    _CHOLMOD_IMPORT_ERROR = str(exc)


def cholmod_available() -> bool:
    """Whether scikit-sparse's CHOLMOD can be used."""
    return _cholmod is not None


@dataclass
class SolverStats:
    """Work counters and seconds spent, per stage."""

    analysis: float = 0.0
    factorization: float = 0.0
    solve: float = 0.0
    factorizations: int = 0
    solves: int = 0
    warnings: list[str] = field(default_factory=list)


def split_fixed(
    L: sp.csr_matrix, fixed: NDArray[np.bool_]
) -> tuple[sp.csc_matrix, sp.csc_matrix, NDArray[np.int64], NDArray[np.int64]]:
    """Rows of free points of ``L``, split into free and fixed columns.

    Parameters
    ----------
    L : scipy.sparse.csr_matrix, shape (n, n)
    fixed : ndarray of bool, shape (n,)

    Returns
    -------
    L_F, L_C : scipy.sparse.csc_matrix
        ``L[free][:, free]`` and ``L[free][:, fixed]``.
    free, fixed_idx : ndarray of int
    """
    free = np.flatnonzero(~fixed)
    fixed_idx = np.flatnonzero(fixed)
    rows = L[free]
    return rows[:, free].tocsc(), rows[:, fixed_idx].tocsc(), free, fixed_idx


class NormalEquations:
    """``(M + lambda diag(d2)) X = lambda diag(d2) P + b`` for many lambdas (report eq. 17).

    Parameters
    ----------
    M : scipy.sparse matrix, shape (m, m)
        ``L_F^T L_F`` (symmetric positive semi-definite).
    d2 : ndarray, shape (m,)
        Squared weights ``omega_i^2`` of the free points (positive).
    method : {"cholmod", "superlu"}
        Requested solver; ``"cholmod"`` falls back to SuperLU with a warning when scikit-sparse
        is missing.
    """

    def __init__(
        self, M: sp.spmatrix, d2: NDArray[np.float64], method: Literal["cholmod", "superlu"]
    ) -> None:
        self.stats = SolverStats()
        if method == "cholmod" and _cholmod is None:
            self.stats.warnings.append(
                f"scikit-sparse (CHOLMOD) is not available ({_CHOLMOD_IMPORT_ERROR}); "
                "used SciPy's SuperLU instead"
            )
            method = "superlu"
        self.method: Literal["cholmod", "superlu"] = method
        m = M.shape[0]
        self.d2 = np.asarray(d2, dtype=np.float64)
        pattern = (sp.csc_matrix(M) + sp.diags(self.d2)).tocsc()
        pattern.sum_duplicates()
        pattern.sort_indices()
        self._A = pattern
        # positions of the diagonal entries inside the CSC data array
        cols = np.repeat(np.arange(m), np.diff(pattern.indptr))
        diag_pos = np.flatnonzero(pattern.indices == cols)
        self._diag_pos = diag_pos[np.argsort(cols[diag_pos])]
        self._M_data = pattern.data.copy()
        self._M_data[self._diag_pos] = sp.csc_matrix(M).diagonal()
        self._factor: Any = None
        self.M_fro = float(np.sqrt(np.sum(self._M_data**2)))
        if self.method == "cholmod":
            t0 = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                self._factor = _cholmod.analyze(pattern, mode="auto")
            self.stats.analysis += time.perf_counter() - t0

    @property
    def size(self) -> int:
        """Number of unknown points."""
        return int(self._A.shape[0])

    def _matrix(self, lam: float) -> sp.csc_matrix:
        A = self._A
        data = self._M_data.copy()
        data[self._diag_pos] += lam * self.d2
        return sp.csc_matrix((data, A.indices, A.indptr), shape=A.shape)

    def solve(self, lam: float, rhs: NDArray[np.float64]) -> NDArray[np.float64]:
        """Factor ``M + lam diag(d2)`` (numerically) and solve for all columns of ``rhs``.

        Parameters
        ----------
        lam : float
            Regularization parameter, ``> 0`` (or ``0`` when ``M`` is definite).
        rhs : ndarray, shape (m, s)

        Returns
        -------
        ndarray, shape (m, s)

        Raises
        ------
        SolverError
            When the matrix is not positive definite or the solve gives non-finite values.
        """
        A = self._matrix(lam)
        t0 = time.perf_counter()
        try:
            if self.method == "cholmod":
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    self._factor.cholesky_inplace(A)
            else:
                self._factor = spla.splu(
                    A,
                    permc_spec="MMD_AT_PLUS_A",
                    diag_pivot_thresh=0.0,
                    options={"SymmetricMode": True},
                )
        except Exception as exc:  # CholmodNotPositiveDefiniteError, RuntimeError (singular)
            raise SolverError(
                f"the normal equations could not be factored at lambda={lam:.6g}: {exc}",
                field="params",
            ) from exc
        t1 = time.perf_counter()
        self.stats.factorization += t1 - t0
        self.stats.factorizations += 1
        x = self._factor(rhs) if self.method == "cholmod" else self._factor.solve(rhs)
        x = np.asarray(x, dtype=np.float64).reshape(rhs.shape)
        self.stats.solve += time.perf_counter() - t1
        self.stats.solves += 1
        if not np.all(np.isfinite(x)):
            raise SolverError(
                f"the solver returned non-finite values at lambda={lam:.6g}", field="params"
            )
        return x
