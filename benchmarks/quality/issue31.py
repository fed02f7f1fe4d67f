"""``python -m benchmarks.quality.issue31 --half calibration|test|all [--tag before]``.

Issue 31's table: geosmooth's default (no smoothing parameter) on the issue's families
(:data:`benchmarks.quality.families.CASES31`: CAD shapes under uniform Gaussian noise, quantized
coordinates, high noise, GPS-like tracks with corners, clouds with stray points, noise-free
inputs), against Taubin with fixed settings (lambda 0.5, mu -0.53, 10 and 50 iterations:
trimesh's ``filter_taubin`` on meshes, Open3D's cloud ``smooth_taubin`` with 20 neighbours on
clouds, the same uniform-Laplacian steps on a curve's edge graph), each peer run in a forked
child. Scores and targets: :mod:`benchmarks.quality.targets`. Writes
``<out>/issue31-<tag>[-<half>]-<date>.md`` and ``.json`` (the halves in separate tables). No
swept peers and no cache: a run takes a few CPU minutes.
"""

from __future__ import annotations

import argparse
import datetime as dt
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from benchmarks.measure import machine_info
from benchmarks.quality.cases import Case, make_case
from benchmarks.quality.families import KIND, PHENOMENON, half_of, issue31_cases
from benchmarks.quality.issue31table import render
from benchmarks.quality.peers import run_isolated
from benchmarks.quality.run import write_tables
from benchmarks.quality.shapes import Shape
from benchmarks.quality.targets import Issue31Scorer, checks, flags
from service.core import Geometry, SmoothingParams, smooth

__all__ = ["TAUBIN", "graph_taubin", "main", "run_case", "taubin"]

FloatArray = NDArray[np.float64]
RESULTS = Path(__file__).resolve().parent / "results"
#: Fixed Taubin settings: lambda, mu (pass band 0.1), iterations (shrink + inflate pairs).
TAUBIN_ITERATIONS = (10, 50)
TAUBIN: dict[str, Any] = {"lambda": 0.5, "mu": -0.53, "iterations": TAUBIN_ITERATIONS}
CLOUD_KNN = 20
REPORT_KEYS = ("sigma_estimate", "noise_found", "tau", "lambda", "warnings", "shape_warnings",
               "outlier_count", "data_weights", "rms_displacement", "max_displacement",
               "tau_how")


def graph_taubin(P: FloatArray, edges: NDArray[np.int64], iterations: int, lam: float,
                 mu: float) -> FloatArray:
    """Taubin's lambda / mu steps with the uniform Laplacian of an edge graph (a curve)."""
    n = len(P)
    deg = np.bincount(edges.ravel(), minlength=n).astype(np.float64)
    X = P.copy()

    def lap(Y: FloatArray) -> FloatArray:
        S = np.zeros_like(Y)
        np.add.at(S, edges[:, 0], Y[edges[:, 1]])
        np.add.at(S, edges[:, 1], Y[edges[:, 0]])
        return np.divide(S, deg[:, None], out=Y.copy(), where=deg[:, None] > 0) - Y

    for _ in range(iterations):
        X = X + lam * lap(X)
        X = X + mu * lap(X)
    return X


def _taubin_run(P: FloatArray, shape: Shape, s: dict[str, Any]) -> FloatArray:
    it, lam, mu = s["iterations"], s["lambda"], s["mu"]
    if shape.faces is not None:
        from benchmarks.peers import _tm_taubin

        return _tm_taubin(P, shape.faces, {"iterations": it, "lambda": lam, "mu": mu})
    if shape.edges is not None:
        return graph_taubin(P, shape.edges, it, lam, mu)
    from benchmarks.quality.peers import _o3d_pc_taubin

    return _o3d_pc_taubin(P, shape, {"iterations": it, "lambda": lam, "mu": mu,
                                     "knn": CLOUD_KNN})


def taubin(case: Case, iterations: int) -> FloatArray:
    """Fixed-setting Taubin on the case's noisy points, in a forked child."""
    s = {"iterations": iterations, "lambda": TAUBIN["lambda"], "mu": TAUBIN["mu"]}
    return run_isolated(_taubin_run, case.points, case.shape, s)


def run_case(key: str) -> dict[str, Any]:
    """The default and the two Taubin settings on one case, scored (JSON-ready)."""
    case = make_case(key)
    scorer = Issue31Scorer(case)
    shape_key = key.split("/")[0]
    out: dict[str, Any] = {
        "key": key, "half": half_of(key), "phenomenon": PHENOMENON[key], "kind": KIND[shape_key],
        "label": case.label, "n": case.n, "noise": case.noise, "level": case.level,
        "h": case.shape.h, "sigma": case.sigma, "sigma_h": case.sigma / case.shape.h,
        "strays": int(case.outliers.sum()), "source": case.shape.source,
    }
    geometry = Geometry(case.points, faces=case.shape.faces, edges=case.shape.edges)
    t0 = time.process_time()
    try:
        res = smooth(geometry, SmoothingParams())
    except Exception as exc:  # a failure of the default is a result
        out.update(error=f"{type(exc).__name__}: {exc}", auto=None)
        return out
    out["cpu_seconds"] = time.process_time() - t0
    rep = res.report()
    report = {k: rep.get(k) for k in REPORT_KEYS}
    auto = scorer.score(res.points)
    flag = flags(rep)
    sigma_hat = rep.get("sigma_estimate")
    out.update(auto=auto, report=report, flags=flag, sigma_hat=sigma_hat)
    tb: dict[str, Any] = {}
    if case.noise != "clean":
        for it in TAUBIN_ITERATIONS:
            try:
                tb[f"x{it}"] = scorer.score(taubin(case, it))
            except RuntimeError as exc:
                tb[f"x{it}"] = {"error": str(exc)}
    out["taubin"] = tb
    out["checks"] = checks(case, auto, tb, sigma_hat, flag)
    return out


def _commit() -> str | None:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, check=True, cwd=Path(__file__).parent).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None


def main(argv: list[str] | None = None) -> int:
    """Run the issue-31 table on one half or both; returns the exit status."""
    ap = argparse.ArgumentParser(prog="python -m benchmarks.quality.issue31", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--half", choices=("calibration", "test", "all"), default="all")
    ap.add_argument("--cases", nargs="+", metavar="KEY", help="a subset of the half's cases")
    ap.add_argument("--out", type=Path, default=RESULTS, help="results directory")
    ap.add_argument("--tag", default="run", help="name part of the output (e.g. 'before')")
    args = ap.parse_args(argv)
    keys = args.cases or issue31_cases(args.half)
    t0 = time.perf_counter()
    cpu0 = time.process_time()
    results = []
    for i, key in enumerate(keys, 1):
        t = time.perf_counter()
        results.append(run_case(key))
        print(f"[{i}/{len(keys)}] {key}: {time.perf_counter() - t:.1f} s", file=sys.stderr,
              flush=True)
    doc = {"machine": machine_info(), "commit": _commit(), "half": args.half,
           "taubin": TAUBIN, "cloud_knn": CLOUD_KNN, "cases": results,
           "seconds": time.perf_counter() - t0, "cpu_seconds_parent": time.process_time() - cpu0,
           "load_end": list(os.getloadavg())}
    day = dt.datetime.now(dt.UTC).strftime("%Y-%m-%d")
    stem = f"issue31-{args.tag}" + ("" if args.half == "all" else f"-{args.half}") + f"-{day}"
    print(write_tables(args.out, stem, doc, render))
    print(f"wrote {args.out / stem}.md and .json ({doc['seconds']:.0f} s)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
