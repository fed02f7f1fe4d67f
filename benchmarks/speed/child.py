"""One job of the speed benchmark in a fresh interpreter (own peak RSS).

Usage (internal): ``python -m benchmarks.speed.child SPEC.json OUT.json``.

Measured in this one process, in order: the operator build; the tau-constrained smoothing on
the chosen path (operator prebuilt, analysis cache empty) and its peak RSS; one analysis +
factorization + solve at the lambda found (CHOLMOD, same operator, cache emptied again); for
meshes with ground truth, Open3D's Laplacian filter (10 iterations) on the same mesh.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.measure import self_peak_rss_mb
from benchmarks.speed.jobs import Job, build_input, ground_truth
from service.core import SmoothingParams, smooth
from service.core.linalg import cache
from service.core.operator.build import build_operator

__all__ = ["main", "run_job"]

PATHS: dict[str, dict[str, Any]] = {
    "auto": {},
    "direct": {"solver": "cholmod"},
    "cg": {"solver": "cg"},
    "windowed-sinc": {"method": "windowed-sinc"},
}


def _rms_error(X: np.ndarray, truth: np.ndarray | None) -> float | None:
    if truth is None:
        return None
    return float(np.sqrt(np.mean(np.sum((X - truth) ** 2, axis=1))))


def _open3d(points: np.ndarray, faces: np.ndarray) -> tuple[float, np.ndarray] | None:
    try:
        import open3d as o3d
    except ImportError:
        return None
    mesh = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(points), o3d.utility.Vector3iVector(faces.astype(np.int32))
    )
    t0 = time.perf_counter()
    out = mesh.filter_smooth_laplacian(number_of_iterations=10)
    seconds = time.perf_counter() - t0
    return seconds, np.asarray(out.vertices)


def run_job(spec: dict[str, Any]) -> dict[str, Any]:
    """Measure one job (see the module docstring)."""
    job = Job(**spec["job"])
    path = spec["path"]
    g, rms = build_input(job)
    truth = ground_truth(job)
    base = {**job.params, **PATHS[path]}
    if spec.get("search"):
        base["search"] = spec["search"]
    params = SmoothingParams(rms=rms, **base)
    cache.clear()
    t0 = time.perf_counter()
    op = build_operator(g, params)
    build = time.perf_counter() - t0
    res = smooth(g, params, operator=op)
    rss = self_peak_rss_mb()
    out: dict[str, Any] = {
        "name": job.name, "path": path, "n": g.n, "kind": g.kind, "build": build,
        "whole": res.timings["total"], "timings": res.timings, "lam": res.lam,
        "relative_error": res.relative_error, "converged": res.converged,
        "iterations": res.iterations, "factorizations": res.factorizations,
        "solves": res.solves, "matvecs": res.matvecs, "solver": res.solver,
        "rss_mb": rss, "error_ours": _rms_error(res.points, truth),
        "error_input": _rms_error(g.points, truth),
    }  # fmt: skip
    cache.analyses.clear()
    one_params = SmoothingParams(lam=res.lam, solver="cholmod", **job.params)
    one = smooth(g, one_params, operator=op)
    out["one_direct"] = one.timings["total"]
    out["ratio_one"] = out["whole"] / one.timings["total"]
    if spec.get("open3d") and g.faces is not None and truth is not None:
        peer = _open3d(g.points, g.faces)
        if peer is not None:
            out["open3d_seconds"], X = peer
            out["error_open3d"] = _rms_error(X, truth)
            out["ratio_open3d"] = (build + out["whole"]) / peer[0]
    return out


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    spec = json.loads(Path(args[0]).read_text())
    out = run_job(spec)
    out["rss_self_mb"] = self_peak_rss_mb()
    Path(args[1]).write_text(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
