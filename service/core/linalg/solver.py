"""Linear solvers for ``K(lambda) X = R`` with ``K(lambda) = M + lambda diag(d2)`` (report eq. 17).

Two paths, one interface (:class:`LinearSolver`):

* :class:`Direct`: sparse Cholesky (CHOLMOD via scikit-sparse; the symbolic analysis done once
  per sparsity pattern and cached, see :mod:`service.core.linalg.cache`) or SciPy's SuperLU (the
  fallback, selectable by name and used with a warning when scikit-sparse cannot be imported).
  A factorization of ``K(lambda_0)`` is reused at a nearby ``lambda`` as the preconditioner of
  CG (:func:`service.core.linalg.krylov.pcg`) when the predicted CG work is cheaper than a new
  numeric factorization; the answer is exact to the same bound either way.
* :class:`MatrixFree`: Jacobi-preconditioned CG with products by ``M`` only, O(n) memory,
  warm-started across lambda.

Nothing outside this module touches the scikit-sparse API (it changed in 0.5).
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray

from service.core.errors import SolverError
from service.core.linalg.gram import Gram, explicit
from service.core.linalg.krylov import pcg
from service.core.warnings import EngineWarning, warning

__all__ = [
    "Direct",
    "Gram",
    "Lanczos",
    "LinearSolver",
    "MatrixFree",
    "SolverStats",
    "cholmod_available",
    "split_fixed",
]

Array = NDArray[np.float64]
#: Relative accuracy of every solve, in the ``D``-norm of the solution (bound of krylov.pcg).
SOLVE_RTOL = 1e-10
#: Most CG steps preconditioned by an existing factorization taken instead of a new one.
REUSE_MAX_STEPS = 10

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
    matvec: float = 0.0
    factorizations: int = 0
    solves: int = 0
    matvecs: int = 0
    warnings: list[EngineWarning] = field(default_factory=list)


def split_fixed(
    L: sp.csr_matrix, fixed: NDArray[np.bool_]
) -> tuple[sp.csc_matrix, sp.csc_matrix, NDArray[np.int64], NDArray[np.int64]]:
    """Rows of free points of ``L``, split into free and fixed columns.

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


class LinearSolver:
    """Common part: ``M`` (CSR for products), ``d2``, work counters.

    Parameters
    ----------
    M : sparse matrix, shape (m, m)
        Symmetric positive semi-definite.
    d2 : ndarray, shape (m,)
        Positive diagonal of ``D^2``.
    """

    name: str = ""
    path: Literal["direct", "matrix-free"] = "direct"

    def __init__(self, M: sp.spmatrix | Gram, d2: Array, stats: SolverStats | None = None) -> None:
        self.M = M if isinstance(M, Gram) else sp.csr_matrix(M)
        self.d2 = np.asarray(d2, dtype=np.float64)
        self.stats = stats if stats is not None else SolverStats()

    @property
    def size(self) -> int:
        return int(self.M.shape[0])

    def matvec(self, X: Array) -> Array:
        """``M X`` (counted)."""
        t0 = time.perf_counter()
        out = np.asarray(self.M @ X)
        self.stats.matvec += time.perf_counter() - t0
        self.stats.matvecs += 1
        return out

    def operator(self, lam: float) -> Any:
        d2 = self.d2[:, None]
        return lambda X: self.matvec(X) + lam * d2 * X

    def solve(
        self, lam: float, R: Array, x0: Array | None = None, offset: Array | None = None
    ) -> Array:
        """``X = K(lam)^-1 R`` with ``||D (X - X*)|| <= SOLVE_RTOL ||D (X* - offset)||``.

        Iterative methods solve for ``X - offset`` (so the accuracy is relative to the
        deviation from ``offset``, e.g. ``E = U - U0``); ``x0`` is a starting guess for ``X``.
        """
        raise NotImplementedError

    def _iterate(
        self,
        lam: float,
        R: Array,
        x0: Array | None,
        offset: Array | None,
        precond: Any,
        maxiter: int,
        bound: Any = None,
    ) -> tuple[Array, bool]:
        K = self.operator(lam)
        if offset is None:
            X, _, ok = pcg(K, R, precond, lam, self.d2, x0, SOLVE_RTOL, maxiter, bound)
            return X, ok
        y0 = None if x0 is None else x0 - offset
        Y, _, ok = pcg(K, R - K(offset), precond, lam, self.d2, y0, SOLVE_RTOL, maxiter, bound)
        return offset + Y, ok

    @staticmethod
    def _check(X: Array, lam: float) -> Array:
        if not np.all(np.isfinite(X)):
            raise SolverError(
                f"the solver returned non-finite values at lambda={lam:.6g}", field="params"
            )
        return X


class MatrixFree(LinearSolver):
    """Jacobi-preconditioned CG on ``K(lambda)``; O(n) memory, no factorization."""

    name = "cg"
    path = "matrix-free"

    def __init__(self, M: sp.spmatrix | Gram, d2: Array, maxiter: int = 20000) -> None:
        super().__init__(M, d2)
        self.diag = self.M.diagonal()
        self.maxiter = maxiter

    def solve(
        self, lam: float, R: Array, x0: Array | None = None, offset: Array | None = None
    ) -> Array:
        inv = 1.0 / (self.diag + lam * self.d2)[:, None]
        X, ok = self._iterate(lam, R, x0, offset, lambda Q: inv * Q, self.maxiter)
        if not ok:
            self.stats.warnings.append(warning(
                "solver-accuracy",
                f"conjugate gradients did not reach the accuracy bound at lambda={lam:.6g} "
                f"in {self.maxiter} products",
                lam=lam, products=self.maxiter,
            ))  # fmt: skip
        return self._check(X, lam)


class Lanczos(MatrixFree):
    """The matrix-free solver of a run whose solution came from one Lanczos run (issue 30,
    :mod:`service.core.search.one_run`): reported as ``"lanczos"``; later solves are CG's."""

    name = "lanczos"


class Direct(LinearSolver):
    """Sparse Cholesky (CHOLMOD) or SuperLU of ``K(lambda)``, reused at nearby lambdas.

    Parameters
    ----------
    M, d2
        See :class:`LinearSolver`.
    method : {"cholmod", "superlu"}
        ``"cholmod"`` falls back to SuperLU with a warning when scikit-sparse is missing.
    reuse : bool
        Reuse a factorization at a nearby lambda through preconditioned CG when cheaper
        (``False``: one numeric factorization per distinct lambda, as in the report).
    symbolic : callable, optional
        ``pattern -> analyzed CHOLMOD factor`` (the analysis cache); default: analyze here.
    """

    path = "direct"

    def __init__(
        self,
        M: sp.spmatrix | Gram,
        d2: Array,
        method: Literal["cholmod", "superlu"] = "cholmod",
        *,
        reuse: bool = True,
        symbolic: Any = None,
    ) -> None:
        super().__init__(M, d2)
        if method == "cholmod" and _cholmod is None:
            self.stats.warnings.append(warning(
                "solver-fallback",
                f"scikit-sparse (CHOLMOD) is not available ({_CHOLMOD_IMPORT_ERROR}); "
                "used SciPy's SuperLU instead",
            ))  # fmt: skip
            method = "superlu"
        self.name = method
        self.reuse = reuse
        self._symbolic = symbolic
        self._factor: Any = None
        self.lam_factored: float | None = None
        self.pattern: sp.csc_matrix | None = None

    def _setup(self) -> None:
        """Form ``M``, the pattern of ``K`` and (CHOLMOD) its symbolic analysis, once, on the
        first factorization: a solver chosen but not used (e.g. replaced by the matrix-free
        path after the lambda estimate) costs nothing."""
        M = explicit(self.M)
        pattern = (sp.csc_matrix(M) + sp.diags(self.d2)).tocsc()
        pattern.sum_duplicates()
        pattern.sort_indices()
        self.pattern = pattern
        cols = np.repeat(np.arange(self.size), np.diff(pattern.indptr))
        diag_pos = np.flatnonzero(pattern.indices == cols)
        self._diag_pos = diag_pos[np.argsort(cols[diag_pos])]
        self._M_data = pattern.data.copy()
        self._M_data[self._diag_pos] = M.diagonal()
        if self.name == "cholmod" and self._factor is None:
            t0 = time.perf_counter()
            symbolic = self._symbolic if self._symbolic is not None else analyze
            self._factor = symbolic(pattern)
            self.stats.analysis += time.perf_counter() - t0

    def with_weights(self, d2: Array) -> Direct:
        """The same solver for ``M + lambda diag(d2)``: same pattern, no new analysis."""
        new = Direct.__new__(Direct)
        new.__dict__.update(self.__dict__)
        new.d2 = np.asarray(d2, dtype=np.float64)
        new.stats = SolverStats()
        new.lam_factored = None
        has = self.name == "cholmod" and self._factor is not None
        new._factor = self._factor.copy() if has else None
        return new

    def matrix(self, lam: float) -> sp.csc_matrix:
        """``K(lam)`` in CSC with the analysed pattern."""
        if self.pattern is None:
            self._setup()
        A = self.pattern
        assert A is not None
        data = self._M_data.copy()
        data[self._diag_pos] += lam * self.d2
        return sp.csc_matrix((data, A.indices, A.indptr), shape=A.shape)

    def factor(self, lam: float) -> None:
        """Numeric factorization of ``K(lam)``."""
        A = self.matrix(lam)
        t0 = time.perf_counter()
        try:
            if self.name == "cholmod":
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
            self.lam_factored = None
            raise SolverError(
                f"the normal equations could not be factored at lambda={lam:.6g}: {exc}",
                field="params",
            ) from exc
        self.stats.factorization += time.perf_counter() - t0
        self.stats.factorizations += 1
        self.lam_factored = lam

    def apply_factor(self, R: Array) -> Array:
        """``K(lambda_factored)^-1 R`` (counted as one solve)."""
        t0 = time.perf_counter()
        f = self._factor
        X = f(R) if self.name == "cholmod" else f.solve(np.asfortranarray(R))
        self.stats.solve += time.perf_counter() - t0
        self.stats.solves += 1
        return np.asarray(X, dtype=np.float64).reshape(R.shape)

    def _factor_bound(self, lam: float) -> Any:
        """Error bound with the factor of ``K(lambda_0)`` as preconditioner.

        Per eigenmode the error and the preconditioned residual differ by the factor
        ``(mu + lambda_0) / (mu + lambda) <= max(1, lambda_0 / lambda)``, so
        ``||D e|| <= max(1, lambda_0 / lambda) ||D Z||`` (rigorous, and far tighter than
        ``||D^-1 R|| / lambda`` when the residual is made of high frequencies).
        """
        assert self.lam_factored is not None
        scale = max(1.0, self.lam_factored / lam)
        d2 = self.d2
        return lambda Rk, Zk: scale * math.sqrt(float(np.einsum("ij,ij,i->", Zk, Zk, d2)))

    def _cg_steps(self, lam: float, R: Array, x0: Array | None, offset: Array | None) -> float:
        """Predicted CG steps preconditioned by the current factor (``inf``: none usable).

        CG contracts the error by ``q = (sqrt(rho) - 1) / (sqrt(rho) + 1)`` per step with
        ``rho = max(lambda / lambda_0, lambda_0 / lambda)``, from the bound of ``x0`` (one
        solve) down to :data:`SOLVE_RTOL`.
        """
        if not self.reuse or self.lam_factored is None:
            return math.inf
        rho = max(lam / self.lam_factored, self.lam_factored / lam)
        q = (math.sqrt(rho) - 1.0) / (math.sqrt(rho) + 1.0)
        reduction = SOLVE_RTOL
        if x0 is not None:
            ref = x0 if offset is None else x0 - offset
            res = R - self.operator(lam)(x0)
            size = float(np.linalg.norm(np.sqrt(self.d2)[:, None] * ref))
            err = self._factor_bound(lam)(res, self.apply_factor(res))
            reduction = min(1.0, SOLVE_RTOL * size / err) if err > 0 else 1.0
        if q <= 0 or reduction >= 1:
            return 1.0
        if not (reduction > 0.0 and q < 1.0):  # lambdas decades apart (q rounds to 1): refactor
            return math.inf
        return 1 + math.ceil(math.log(reduction) / math.log(q))

    def solve(
        self, lam: float, R: Array, x0: Array | None = None, offset: Array | None = None
    ) -> Array:
        """Direct solve at the factored lambda; elsewhere CG preconditioned by the factor when
        at most :data:`REUSE_MAX_STEPS` steps are predicted (a new factorization costs 12-40
        solves on the benchmark's meshes; the rule uses no timings, so runs are reproducible),
        else a new numeric factorization."""
        if self.lam_factored != lam and self._cg_steps(lam, R, x0, offset) > REUSE_MAX_STEPS:
            self.factor(lam)
        if self.lam_factored == lam:
            return self._check(self.apply_factor(R), lam)
        X, ok = self._iterate(
            lam, R, x0, offset, self.apply_factor, 4 * REUSE_MAX_STEPS, self._factor_bound(lam)
        )
        if not ok:  # the prediction was wrong: factor here after all
            self.factor(lam)
            X = self.apply_factor(R)
        return self._check(X, lam)


#: Unknowns from which METIS ordering pays for its slower analysis (service/core/README.md).
METIS_FROM = 150_000


def ordering_for(size: int) -> str:
    """The fill-reducing ordering: AMD for small systems, METIS (nested dissection) above
    :data:`METIS_FROM` unknowns (3.4x fewer flops at 655K, analysis 10x slower)."""
    return "metis" if size >= METIS_FROM else "amd"


def analyze(pattern: sp.csc_matrix, ordering: str | None = None) -> Any:
    """CHOLMOD symbolic analysis (fill-reducing ordering, supernodal structure)."""
    ordering = ordering if ordering is not None else ordering_for(pattern.shape[0])
    assert _cholmod is not None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return _cholmod.analyze(pattern, mode="supernodal", ordering_method=ordering)
