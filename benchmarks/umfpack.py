"""A minimal ctypes binding to the system UMFPACK (SuiteSparse), for benchmarks only.

scikit-umfpack 0.4.2 does not build on Debian 12: its meson build looks for an ``umfpack``
pkg-config/cmake dependency that SuiteSparse 5.12 does not ship, and its SWIG step then fails with
"umfpack_dep not found in dependencies". The UMFPACK library itself is present (``libumfpack.so.5``
from ``libsuitesparse-dev``, which the service needs for CHOLMOD anyway), so this module calls its
C API directly: one symbolic analysis (``umfpack_di_symbolic``), then per matrix one numeric
factorization (``umfpack_di_numeric``) and one solve per right-hand side (``umfpack_di_solve``),
all with UMFPACK's default control parameters (automatic strategy, iterative refinement on).
"""

from __future__ import annotations

import ctypes
import ctypes.util
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

__all__ = ["UmfpackError", "UmfpackLU", "load_umfpack", "umfpack_version"]

UMFPACK_CONTROL = 20
UMFPACK_INFO = 90
UMFPACK_A = 0  # solve A x = b
_LIB: Any = None


class UmfpackError(RuntimeError):
    """UMFPACK could not be loaded, or a call returned an error status."""


def load_umfpack() -> Any:
    """Load ``libumfpack`` once and declare the prototypes used here.

    Raises
    ------
    UmfpackError
        When no UMFPACK shared library is found.
    """
    global _LIB
    if _LIB is not None:
        return _LIB
    names = [ctypes.util.find_library("umfpack"), "libumfpack.so.5", "libumfpack.so.6"]
    lib = None
    for name in names:
        if not name:
            continue
        try:
            lib = ctypes.CDLL(name)
            break
        except OSError:
            continue
    if lib is None:
        raise UmfpackError("libumfpack not found (install libsuitesparse-dev or libumfpack5)")
    i32p = np.ctypeslib.ndpointer(np.int32, flags="C_CONTIGUOUS")
    f64p = np.ctypeslib.ndpointer(np.float64, flags="C_CONTIGUOUS")
    vpp = ctypes.POINTER(ctypes.c_void_p)
    lib.umfpack_di_defaults.argtypes = [f64p]
    lib.umfpack_di_defaults.restype = None
    lib.umfpack_di_symbolic.argtypes = [
        ctypes.c_int,
        ctypes.c_int,
        i32p,
        i32p,
        f64p,
        vpp,
        f64p,
        f64p,
    ]
    lib.umfpack_di_symbolic.restype = ctypes.c_int
    lib.umfpack_di_numeric.argtypes = [i32p, i32p, f64p, ctypes.c_void_p, vpp, f64p, f64p]
    lib.umfpack_di_numeric.restype = ctypes.c_int
    lib.umfpack_di_solve.argtypes = [
        ctypes.c_int,
        i32p,
        i32p,
        f64p,
        f64p,
        f64p,
        ctypes.c_void_p,
        f64p,
        f64p,
    ]
    lib.umfpack_di_solve.restype = ctypes.c_int
    lib.umfpack_di_free_symbolic.argtypes = [vpp]
    lib.umfpack_di_free_symbolic.restype = None
    lib.umfpack_di_free_numeric.argtypes = [vpp]
    lib.umfpack_di_free_numeric.restype = None
    _LIB = lib
    return lib


def umfpack_version() -> str | None:
    """Version of the loaded UMFPACK library (from its shared-object name), or ``None``."""
    path = ctypes.util.find_library("umfpack")
    try:
        load_umfpack()
    except UmfpackError:
        return None
    return path or "libumfpack"


class UmfpackLU:
    """LU factorizations of matrices sharing one sparsity pattern.

    Parameters
    ----------
    pattern : scipy.sparse matrix, shape (n, n)
        Matrix whose pattern (CSC, sorted indices) every later matrix shares; its values are
        used for the symbolic analysis.
    """

    def __init__(self, pattern: sp.spmatrix) -> None:
        self._lib = load_umfpack()
        A = sp.csc_matrix(pattern)
        A.sort_indices()
        self.n = int(A.shape[0])
        self._Ap = np.ascontiguousarray(A.indptr, dtype=np.int32)
        self._Ai = np.ascontiguousarray(A.indices, dtype=np.int32)
        self._Ax = np.ascontiguousarray(A.data, dtype=np.float64)
        self._control = np.zeros(UMFPACK_CONTROL)
        self._info = np.zeros(UMFPACK_INFO)
        self._lib.umfpack_di_defaults(self._control)
        self._symbolic = ctypes.c_void_p()
        self._numeric = ctypes.c_void_p()
        status = self._lib.umfpack_di_symbolic(
            self.n,
            self.n,
            self._Ap,
            self._Ai,
            self._Ax,
            ctypes.byref(self._symbolic),
            self._control,
            self._info,
        )
        if status != 0:
            raise UmfpackError(f"umfpack_di_symbolic failed with status {status}")

    def factor(self, data: NDArray[np.float64]) -> None:
        """Numeric factorization of the matrix with this pattern and values ``data``."""
        self._free_numeric()
        self._Ax = np.ascontiguousarray(data, dtype=np.float64)
        status = self._lib.umfpack_di_numeric(
            self._Ap,
            self._Ai,
            self._Ax,
            self._symbolic,
            ctypes.byref(self._numeric),
            self._control,
            self._info,
        )
        if status != 0:  # 1 = singular matrix (a warning in UMFPACK terms)
            raise UmfpackError(f"umfpack_di_numeric failed with status {status}")

    def solve(self, rhs: NDArray[np.float64]) -> NDArray[np.float64]:
        """Solve for every column of ``rhs`` (shape ``(n,)`` or ``(n, k)``)."""
        B = np.asarray(rhs, dtype=np.float64)
        cols = B.reshape(self.n, -1)
        X = np.empty_like(cols)
        for j in range(cols.shape[1]):
            b = np.ascontiguousarray(cols[:, j])
            x = np.empty(self.n)
            status = self._lib.umfpack_di_solve(
                UMFPACK_A,
                self._Ap,
                self._Ai,
                self._Ax,
                x,
                b,
                self._numeric,
                self._control,
                self._info,
            )
            if status != 0:
                raise UmfpackError(f"umfpack_di_solve failed with status {status}")
            X[:, j] = x
        return X.reshape(B.shape)

    def _free_numeric(self) -> None:
        if self._numeric:
            self._lib.umfpack_di_free_numeric(ctypes.byref(self._numeric))
            self._numeric = ctypes.c_void_p()

    def __del__(self) -> None:
        try:
            self._free_numeric()
            if self._symbolic:
                self._lib.umfpack_di_free_symbolic(ctypes.byref(self._symbolic))
        except Exception:  # pragma: no cover - interpreter shutdown
            pass
