"""The default on point clouds by size (issue 30 item 7: "1M points (cloud): <= 20 s CPU and
<= 1.5 GB"): CPU seconds, peak RSS and the stage breakdown, one child process per size.

The input is ``benchmarks.speed.jobs``' cloud (uniform on the unit sphere, Gaussian noise of
0.3 mean spacings); the distance to the true surface is closed form (``| |x| - 1 |``). Open3D
has no cloud smoother to compare with; its ``estimate_normals`` (k-NN + PCA, 30 neighbours),
the least any cloud smoother does, is timed on the same points in the same process as a scale.

Usage: ``python -m benchmarks.speed.cloud_growth [--sizes 100000,1000000] [--out FILE]``.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["main", "run_size"]

_THREAD_ENV = {
    "GEOSMOOTH_THREADS": "1", "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1",
}  # fmt: skip


def _rms(a: np.ndarray) -> float:
    return float(np.sqrt(np.mean(a**2)))


def _open3d_normals(points: np.ndarray) -> float | None:
    try:
        import open3d as o3d
    except ImportError:
        return None
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    c0 = time.process_time()
    cloud.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(knn=30))
    return time.process_time() - c0


def run_size(n: int) -> dict[str, Any]:
    """Smooth the ``n``-point cloud with no parameter in this process, profiled by stage."""
    import cProfile
    import resource

    from benchmarks.speed.jobs import INPUTS
    from benchmarks.speed.open3d_ratio import _profile_stages
    from service.core import SmoothingParams, smooth

    g, sigma, truth = INPUTS["cloud"](str(n))
    load0 = os.getloadavg()[0]
    prof = cProfile.Profile(time.process_time)
    c0 = time.process_time()
    prof.enable()
    res = smooth(g, SmoothingParams())
    prof.disable()
    cpu = time.process_time() - c0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    report = res.report()
    return {
        "n": n, "cpu": cpu, "load": [load0, os.getloadavg()[0]], "peak_rss_mib": peak,
        "sigma": sigma, "sigma_hat": report.get("sigma_estimate"),
        "surface": {"ours": _rms(np.linalg.norm(res.points, axis=1) - 1),
                    "input": _rms(np.linalg.norm(g.points, axis=1) - 1)},
        "vertex": {"ours": _rms(np.linalg.norm(res.points - truth, axis=1)),
                   "input": _rms(np.linalg.norm(g.points - truth, axis=1))},
        "outliers": report.get("outlier_count"), "solver": res.solver,
        "matvecs": res.matvecs, "profile": _profile_stages(prof),
        "points_sha256": hashlib.sha256(np.ascontiguousarray(res.points).tobytes()).hexdigest(),
        "open3d_estimate_normals_cpu": _open3d_normals(g.points),
    }  # fmt: skip


def _markdown(rows: list[dict[str, Any]]) -> str:
    lines = ["# The default on point clouds (sphere, noise 0.3 spacing)", "",
             "| n | CPU s (load) | peak RSS MiB | products | RMS to surface ours / input "
             "| Open3D estimate_normals CPU s |", "|---|---|---|---|---|---|"]  # fmt: skip
    for r in rows:
        lines.append(
            f"| {r['n']} | {r['cpu']:.2f} ({r['load'][0]:.1f}) | {r['peak_rss_mib']:.0f} | "
            f"{r['matvecs']} | {r['surface']['ours']:.3g} / {r['surface']['input']:.3g} | "
            f"{r['open3d_estimate_normals_cpu'] or float('nan'):.2f} |"
        )
    for r in rows:
        lines += ["", f"## {r['n']} points: CPU by stage (cProfile, cumulative)", "",
                  "| stage | CPU s |", "|---|---|"]  # fmt: skip
        lines += [f"| {k} | {v:.2f} |" for k, v in r["profile"]["stages"].items()]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.speed.cloud_growth")
    ap.add_argument("--sizes", default="100000,1000000")
    ap.add_argument("--out", default="")
    ap.add_argument("--child", type=int, default=0, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(run_size(args.child)))
        return 0
    rows = []
    for n in (int(s) for s in args.sizes.split(",")):
        done = subprocess.run(
            [sys.executable, "-m", "benchmarks.speed.cloud_growth", "--child", str(n)],
            capture_output=True, text=True, env={**os.environ, **_THREAD_ENV}, check=True,
        )  # fmt: skip
        rows.append(json.loads(done.stdout.strip().splitlines()[-1]))
        print(f"{n}: {rows[-1]['cpu']:.1f} s CPU, {rows[-1]['peak_rss_mib']:.0f} MiB", flush=True)
    text = _markdown(rows)
    print(text)
    if args.out:
        Path(args.out).with_suffix(".md").write_text(text)
        Path(args.out).with_suffix(".json").write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
