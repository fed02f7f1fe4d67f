"""Issue 22's table: CPU of a whole smoothing run over Open3D's Laplacian filter x10.

``python -m benchmarks.speed.table [--quick] [--cases NAME,...] [--out DIR]``

Each case runs in a fresh interpreter (niced by the caller), in one process: the input, then
``service.core.smooth`` from scratch (operator build included, as the CLI and the library run
it; threads as the library's default, ``GEOSMOOTH_THREADS``), then Open3D's
``filter_smooth_laplacian(number_of_iterations=10)`` on the same mesh (median of 3; skipped when
open3d is not installed). CPU seconds are ``time.process_time`` (all threads). Also recorded:
products with ``L^T L``, factorizations, ``|phi - tau| / tau``, the stage timings, and each
result's RMS distance to the noise-free surface (ours and Open3D's). Results:
``<out>/table-<date>.json`` and ``.md`` with the load (``uptime``) before and after.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["CASES", "main", "run_case"]

#: name -> (input, parameters); "rms" stands for 1.7 x the noise level (the peer level)
CASES: dict[str, tuple[str, dict[str, Any]]] = {
    "164K default": ("ico:7", {}),
    "164K direct rms": ("ico:7", {"rms": "peer", "solver": "cholmod"}),
    "164K windowed-sinc rms": ("ico:7", {"rms": "peer", "method": "windowed-sinc"}),
    "655K default": ("ico:8", {}),
    "1M torus default": ("torus:1000", {}),
    "1M torus direct": ("torus:1000", {"solver": "cholmod"}),
    "1M torus windowed-sinc rms": ("torus:1000", {"rms": "peer", "method": "windowed-sinc"}),
}
QUICK = {"10K default": ("ico:5", {}), "10K windowed-sinc rms": ("ico:5", {"rms": "peer",
         "method": "windowed-sinc"})}  # fmt: skip


def _rms(X: np.ndarray, truth: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((X - truth) ** 2, axis=1))))


def _open3d(points: np.ndarray, faces: np.ndarray) -> tuple[float, np.ndarray] | None:
    try:
        import open3d as o3d
    except ImportError:
        return None
    mesh = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(points), o3d.utility.Vector3iVector(faces.astype(np.int32))
    )
    cpu = []
    for _ in range(3):
        c0 = time.process_time()
        out = mesh.filter_smooth_laplacian(number_of_iterations=10)
        cpu.append(time.process_time() - c0)
    return float(np.median(cpu)), np.asarray(out.vertices)


def run_case(name: str, inp: str, extra: dict[str, Any]) -> dict[str, Any]:
    """Measure one case in this process (see the module docstring)."""
    from benchmarks.speed.jobs import INPUTS, LEVELS
    from service.core import SmoothingParams, smooth
    from service.core.linalg.threads import thread_counts, use_default_threads

    use_default_threads(os.environ)
    kind, _, arg = inp.partition(":")
    g, sigma, truth = INPUTS[kind](arg)
    assert truth is not None  # synthetic inputs only
    params = dict(extra)
    if params.get("rms") == "peer":
        params["rms"] = LEVELS["peer"] * sigma
    c0, w0 = time.process_time(), time.perf_counter()
    res = smooth(g, SmoothingParams(**params))
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    out: dict[str, Any] = {
        "name": name, "n": g.n, "cpu": cpu, "wall": wall, "solver": res.solver,
        "matvecs": res.matvecs, "factorizations": res.factorizations,
        "relative_error": res.relative_error, "tau": res.tau, "timings": res.timings,
        "error_ours": _rms(res.points, truth), "error_input": _rms(g.points, truth),
        "threads": thread_counts(),
    }  # fmt: skip
    peer = _open3d(g.points, g.faces) if g.faces is not None else None
    if peer is not None:
        out["open3d_cpu"], X = peer
        out["error_open3d"] = _rms(X, truth)
        out["ratio_open3d"] = cpu / out["open3d_cpu"]
    return out


def _uptime() -> str:
    return subprocess.run(["uptime"], capture_output=True, text=True, check=False).stdout.strip()


def _markdown(rows: list[dict[str, Any]], before: str, after: str) -> str:
    lines = [
        f"load before: `{before}`  ", f"load after: `{after}`", "",
        "| case | n | CPU s | wall s | CPU / Open3D x10 | products / factorizations | "
        "|phi-tau|/tau | RMS to surface (ours / Open3D / input) |",
        "|---|---|---|---|---|---|---|---|",
    ]  # fmt: skip
    for r in rows:
        if "cpu" not in r:
            lines.append(f"| {r['name']} | | {r.get('status')} | | | | | |")
            continue
        ratio = f"{r['ratio_open3d']:.1f}" if "ratio_open3d" in r else "-"
        o3d = f"{r['error_open3d']:.3g}" if "error_open3d" in r else "-"
        lines.append(
            f"| {r['name']} | {r['n']} | {r['cpu']:.1f} | {r['wall']:.1f} | {ratio} | "
            f"{r['matvecs']} / {r['factorizations']} | {r['relative_error']:.1e} | "
            f"{r['error_ours']:.3g} / {o3d} / {r['error_input']:.3g} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.speed.table")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--cases", default="")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results"))
    ap.add_argument("--one", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.one:
        name = args.one
        inp, extra = {**CASES, **QUICK}[name]
        print(json.dumps(run_case(name, inp, extra)))
        return 0
    cases = QUICK if args.quick else CASES
    names = [c for c in args.cases.split(",") if c] or list(cases)
    before, rows = _uptime(), []
    for name in names:
        cmd = [sys.executable, "-m", "benchmarks.speed.table", "--one", name]
        done = subprocess.run(cmd, capture_output=True, text=True, check=False, timeout=3600)
        if done.returncode == 0:
            row = json.loads(done.stdout.strip().splitlines()[-1])
        else:
            tail = (done.stderr.strip().splitlines() or ["?"])[-1]
            row = {"name": name, "status": f"error: {tail}"}
        print(json.dumps({k: row.get(k) for k in ("name", "cpu", "wall", "ratio_open3d")}),
              flush=True)  # fmt: skip
        rows.append(row)
    after = _uptime()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    stem = out / f"table-{_dt.date.today().isoformat()}"
    stem.with_suffix(".json").write_text(json.dumps({"load_before": before, "load_after": after,
                                                     "rows": rows}, indent=1))  # fmt: skip
    stem.with_suffix(".md").write_text(_markdown(rows, before, after))
    print(_markdown(rows, before, after))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
