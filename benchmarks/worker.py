"""Child process of the solver table: one solver on one mesh, in a fresh interpreter.

Usage (internal)::

    python -m benchmarks.worker SPEC.json OUT.json

``SPEC`` names the case file (``.npz`` with ``points``, ``faces``), the solver and either ``tau``
(CHOLMOD / SuperLU: our full ``smooth``) or the lambda sequence to replay (UMFPACK / SPQR:
benchmark-only code doing the same work per lambda as our search did).
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from benchmarks.measure import self_peak_rss_mb
from service.core import Geometry, SmoothingParams, smooth
from service.core.linalg.solver import split_fixed
from service.core.operator.build import build_laplacian

__all__ = ["main", "replay", "run_ours"]


def run_ours(geometry: Geometry, tau: float, solver: str) -> dict[str, Any]:
    """Our ``smooth`` with the tau search, using ``solver`` ("cholmod" or "superlu")."""
    # the report's search (one factorization per lambda), which the other solvers replay
    params = SmoothingParams(tau=tau, solver=solver, preset="report")  # type: ignore[arg-type]
    res = smooth(geometry, params)
    t = res.timings
    return {
        "total": t["total"],
        "build": t["neighborhoods"] + t["laplacian"],
        "analysis": t["analysis"],
        "factorization": t["factorization"],
        "solve": t["solve"],
        "search": t["search"],
        "iterations": res.iterations,
        "factorizations": res.factorizations,
        "converged": res.converged,
        "lam": res.lam,
        "phi": res.phi,
        "history": res.history,
        "solver_used": res.solver,
    }


def _system(
    geometry: Geometry,
) -> tuple[sp.csc_matrix, NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], float]:
    """``L_F``, ``omega_F``, ``P_F``, ``-L_C P_C`` exactly as ``smooth`` sets them up."""
    t0 = time.perf_counter()
    L, _, _, _ = build_laplacian(geometry, SmoothingParams(lam=1.0, preset="report"))
    n = geometry.n
    coupled = (np.diff(L.indptr) > 0) | (np.bincount(L.indices, minlength=n) > 0)
    fixed = geometry.fixed_mask() | ~coupled
    L_F, L_C, free, fixed_idx = split_fixed(L, fixed)
    P = geometry.points
    top = np.zeros((free.size, P.shape[1]))
    if fixed_idx.size:
        top = -np.asarray(L_C @ P[fixed_idx])
    return L_F, geometry.omega()[free], P[free], top, time.perf_counter() - t0


def replay(geometry: Geometry, lams: list[float], solver: str) -> dict[str, Any]:
    """Solve eq. (4) for each lambda of ``lams`` with UMFPACK or SuiteSparseQR.

    UMFPACK ("umfpack") factors the normal equations (17): one symbolic analysis, then one
    numeric LU factorization and one solve per lambda. SuiteSparseQR ("spqr") solves the
    stacked least-squares system (16) ``[L_F; sqrt(lam) D] X = [-L_C P_C; sqrt(lam) D P]`` with
    ``SuiteSparseQR_C_backslash`` (a fresh QR per lambda; the QR of a matrix that changes with
    lambda cannot be reused).
    """
    t0 = time.perf_counter()
    L_F, w, P_F, top, build = _system(geometry)
    w2 = w**2
    analysis = factorization = solve = 0.0
    phis: list[float] = []
    if solver == "umfpack":
        from benchmarks.umfpack import UmfpackLU

        M = (L_F.T @ L_F).tocsc()
        M.eliminate_zeros()
        b = np.asarray(L_F.T @ top)
        A = (M + sp.diags(w2)).tocsc()
        A.sum_duplicates()
        A.sort_indices()
        cols = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
        diag = np.flatnonzero(A.indices == cols)
        diag = diag[np.argsort(cols[diag])]
        base = A.data.copy()
        base[diag] -= w2
        ta = time.perf_counter()
        lu = UmfpackLU(A)
        analysis = time.perf_counter() - ta
        for lam in lams:
            data = base.copy()
            data[diag] += lam * w2
            tf = time.perf_counter()
            lu.factor(data)
            ts = time.perf_counter()
            X = lu.solve(lam * w2[:, None] * P_F + b)
            te = time.perf_counter()
            factorization += ts - tf
            solve += te - ts
            phis.append(float(np.sum(w2[:, None] * (X - P_F) ** 2)))
    elif solver == "spqr":
        import sparseqr

        for lam in lams:
            tf = time.perf_counter()
            s = np.sqrt(lam) * w
            A = sp.vstack([L_F, sp.diags(s)]).tocoo()
            B = np.vstack([top, s[:, None] * P_F])
            X = sparseqr.solve(A, B)
            factorization += time.perf_counter() - tf
            if X is None:
                raise RuntimeError(f"SuiteSparseQR failed at lambda={lam:.6g}")
            phis.append(float(np.sum(w2[:, None] * (np.asarray(X) - P_F) ** 2)))
    else:
        raise ValueError(f"unknown solver {solver!r}")
    return {
        "total": time.perf_counter() - t0,
        "build": build,
        "analysis": analysis,
        "factorization": factorization,
        "solve": solve,
        "iterations": len(lams),
        "factorizations": len(lams),
        "phis": phis,
    }


def main(argv: list[str] | None = None) -> int:
    """Entry point of the child process."""
    args = sys.argv[1:] if argv is None else argv
    spec = json.loads(Path(args[0]).read_text())
    with np.load(spec["case"]) as z:
        geometry = Geometry(z["points"], faces=z["faces"])
    rss_before = self_peak_rss_mb()
    solver = spec["solver"]
    if solver in ("cholmod", "superlu"):
        out = run_ours(geometry, float(spec["tau"]), solver)
    else:
        out = replay(geometry, [float(x) for x in spec["lams"]], solver)
    out["rss_before_mb"] = rss_before
    out["rss_self_mb"] = self_peak_rss_mb()
    Path(args[1]).write_text(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
