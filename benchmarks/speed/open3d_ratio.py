"""Issue 30's table: CPU of geosmooth over Open3D's Laplacian filter x10, in one process.

``python -m benchmarks.speed.open3d_ratio [--cases NAME,...] [--profile NAME] [--label L]``

Each case runs in a fresh interpreter (the parent only collects): the input (built as
:mod:`benchmarks.speed.jobs` builds its ``sizes`` inputs: noisy icosphere, noise 0.3 x the mean
edge; 1000 x 1000 torus grid, noise 0.3 x the grid step), then ``service.core.smooth`` from
scratch (operator build included, imports excluded), then Open3D's
``filter_smooth_laplacian(number_of_iterations=10)`` on the same mesh (median of 3), both in
that process. One thread each: ``GEOSMOOTH_THREADS=1``, ``OMP_NUM_THREADS=1`` and friends set
before any import, and :func:`threadpoolctl.threadpool_limits` (1) around both measurements.
CPU seconds are :func:`time.process_time` (all threads of the process). Recorded with each
number: ``os.getloadavg()`` before and after it (two shared cores: absolute seconds inflate
with the load, ratios taken in one process much less). Quality: the RMS distance of the
result's vertices to the noise-free vertices and to the true surface (sphere ``|x| = 1``, torus
``R = 1, r = 0.4`` in closed form), ours and Open3D's.

``--profile NAME``: the case under :mod:`cProfile` (timer ``process_time``), its CPU grouped into
the stages of :data:`STAGES` (cumulative time of the named functions) plus the top functions
of ``service/``. Open3D must be importable (``pip install .[bench]``; ``--o3d-path`` adds a
directory to the children's ``PYTHONPATH``). Results: ``<out>/open3d-ratio-<label>.json`` and
``.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["CASES", "STAGES", "main", "run_case"]

#: name -> (input, parameters); rms "peer" = 1.7 x the noise level (benchmarks.speed.jobs)
CASES: dict[str, tuple[str, dict[str, Any]]] = {
    "164K default": ("ico:7", {}),
    "164K tau given": ("ico:7", {"rms": "peer"}),
    "164K windowed-sinc": ("ico:7", {"rms": "peer", "method": "windowed-sinc"}),
    "1M default": ("torus:1000", {}),
    "1M tau given": ("torus:1000", {"rms": "peer"}),
    "1M windowed-sinc": ("torus:1000", {"rms": "peer", "method": "windowed-sinc"}),
    "10K default": ("ico:5", {}),
    "100K default": ("torus:550", {}),
}
DEFAULT_CASES = [name for name in CASES if name[0] in "1" and not name.startswith(("10K", "100K"))]
#: stage label -> (path suffix of the file, function names); cumulative CPU of each
STAGES: dict[str, tuple[str, tuple[str, ...]]] = {
    "operator (neighbourhoods, weights, L)": ("", ("build_operator",)),
    "1-ring": ("", ("mesh_neighborhoods",)),
    "data weights": ("", ("data_weights",)),
    "noise estimate (auto tau)": ("", ("auto_tau",)),
    "normal frames": ("", ("_frames", "normal_frames_closed")),
    "normal system (A, A^T A)": ("", ("projected_normal_system",)),
    "automatic lambda, factorized path (rule + polish)": ("", ("choose",)),
    "lambda search (factorized path)": ("", ("find_lambda",)),
    "solution": ("", ("solution", "_bounded")),
    "automatic lambda + solution (one run or factorized)": ("", ("choose_and_solve",)),
    "one-run Lanczos, given tau": ("", ("solve_tau",)),
    "tangential step": ("", ("relax_tangential",)),
    "diagnostics + shape checks": ("", ("diagnostics",)),
    "CHOLMOD analysis": ("", ("analyze",)),
    "CHOLMOD factorization": ("", ("factor",)),
    "products with M": ("", ("matvec",)),
}
_THREAD_ENV = {
    "GEOSMOOTH_THREADS": "1", "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1",
}  # fmt: skip


def _load() -> list[float]:
    return [round(x, 2) for x in os.getloadavg()]


def _peak_mib() -> float:
    """Peak resident memory of this process so far (MiB; input, engine and imports)."""
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _rms(A: np.ndarray) -> float:
    return float(np.sqrt(np.mean(A**2)))


def surface_distance(X: np.ndarray, inp: str) -> np.ndarray:
    """Distance of each point to the true surface of input ``inp`` (closed form)."""
    if inp.startswith("ico"):
        return np.abs(np.linalg.norm(X, axis=1) - 1.0)
    rho = np.hypot(X[:, 0], X[:, 1]) - 1.0  # torus R = 1, r = 0.4 (benchmarks.shapes)
    return np.abs(np.hypot(rho, X[:, 2]) - 0.4)


def _quality(X: np.ndarray, truth: np.ndarray, inp: str) -> dict[str, float]:
    return {"vertex": _rms(np.linalg.norm(X - truth, axis=1)),
            "surface": _rms(surface_distance(X, inp))}  # fmt: skip


def _open3d(points: np.ndarray, faces: np.ndarray) -> dict[str, Any] | None:
    try:
        import open3d as o3d
    except ImportError:
        return None
    mesh = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(points), o3d.utility.Vector3iVector(faces.astype(np.int32))
    )
    cpu, loads = [], []
    for _ in range(3):
        loads.append(_load())
        c0 = time.process_time()
        out = mesh.filter_smooth_laplacian(number_of_iterations=10)
        cpu.append(time.process_time() - c0)
    return {"cpu": float(np.median(cpu)), "cpus": cpu, "load": [*loads, _load()],
            "points": np.asarray(out.vertices)}  # fmt: skip


def _profile_stages(prof: Any) -> dict[str, Any]:
    import pstats

    stats = pstats.Stats(prof).stats  # type: ignore[attr-defined]
    stages: dict[str, float] = {}
    top: list[tuple[float, str]] = []
    for (path, line, fn), (_, _, _, cumulative, _) in stats.items():
        for label, (suffix, names) in STAGES.items():
            if fn in names and path.endswith(suffix) and "service" in path:
                stages[label] = stages.get(label, 0.0) + cumulative
        if "/service/" in path:
            top.append((cumulative, f"{path.split('/service/')[-1]}:{line}({fn})"))
    top.sort(reverse=True)
    return {"stages": {k: round(v, 2) for k, v in stages.items()},
            "top": [(round(c, 2), name) for c, name in top[:40]]}  # fmt: skip


def run_case(name: str, profile: bool = False) -> dict[str, Any]:
    """Measure case ``name`` in this process (see the module docstring)."""
    from threadpoolctl import threadpool_limits

    import service.core.linalg.solver  # noqa: F401  (CHOLMOD's pools exist before the limit)
    from benchmarks.speed.jobs import INPUTS, LEVELS
    from service.core import SmoothingParams, smooth

    inp, extra = CASES[name]
    kind, _, arg = inp.partition(":")
    g, sigma, truth = INPUTS[kind](arg)
    assert truth is not None and g.faces is not None
    params = dict(extra)
    if params.get("rms") == "peer":
        params["rms"] = LEVELS["peer"] * sigma
    out: dict[str, Any] = {"name": name, "input": inp, "n": g.n, "params": params}
    with threadpool_limits(1):
        prof = None
        if profile:
            import cProfile

            prof = cProfile.Profile(time.process_time)
        load0 = _load()
        c0, w0 = time.process_time(), time.perf_counter()
        if prof is not None:
            prof.enable()
        res = smooth(g, SmoothingParams(**params))
        if prof is not None:
            prof.disable()
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
        out.update(cpu=cpu, wall=wall, load=[load0, _load()], peak_rss_mib=_peak_mib())
        peer = _open3d(g.points, g.faces)
    report = res.report()
    out.update(
        solver=res.solver, matvecs=res.matvecs, factorizations=res.factorizations,
        lam=res.lam, phi=res.phi, tau=res.tau, relative_error=res.relative_error,
        timings=res.timings, ours=_quality(res.points, truth, inp),
        input_error=_quality(g.points, truth, inp),
        deviation=float(np.sum(g.omega()[:, None] ** 2 * (res.points - g.points) ** 2)),
        tangential=report.get("tangential"),
    )  # fmt: skip
    if prof is not None:
        out["profile"] = _profile_stages(prof)
    if peer is not None:
        out["open3d"] = {"cpu": peer["cpu"], "cpus": peer["cpus"], "load": peer["load"],
                         **_quality(peer["points"], truth, inp)}  # fmt: skip
        out["ratio"] = cpu / peer["cpu"]
    return out


def _markdown(rows: list[dict[str, Any]], label: str) -> str:
    lines = [
        f"# geosmooth vs Open3D filter_smooth_laplacian x10 ({label})", "",
        "| case | n | CPU s (load) | Open3D CPU s | CPU / Open3D | products / factorizations "
        "| RMS to surface: ours / Open3D / input | vertex: ours / Open3D / input |",
        "|---|---|---|---|---|---|---|---|",
    ]  # fmt: skip
    for r in rows:
        if "cpu" not in r:
            lines.append(f"| {r['name']} | | {r.get('status')} | | | | | |")
            continue
        o3 = r.get("open3d") or {}
        ratio = f"**{r['ratio']:.2f}**" if "ratio" in r else "-"
        lines.append(
            f"| {r['name']} | {r['n']} | {r['cpu']:.2f} ({r['load'][0][0]:.1f}) | "
            f"{o3.get('cpu', float('nan')):.3f} | {ratio} | {r['matvecs']} / "
            f"{r['factorizations']} | {r['ours']['surface']:.3g} / "
            f"{o3.get('surface', float('nan')):.3g} / {r['input_error']['surface']:.3g} | "
            f"{r['ours']['vertex']:.3g} / {o3.get('vertex', float('nan')):.3g} / "
            f"{r['input_error']['vertex']:.3g} |"
        )
    for r in rows:
        prof = r.get("profile")
        if prof:
            lines += ["", f"## {r['name']}: CPU by stage (cProfile, cumulative)", "",
                      "| stage | CPU s |", "|---|---|"]  # fmt: skip
            lines += [f"| {k} | {v:.2f} |" for k, v in prof["stages"].items()]
            lines += [f"| total | {r['cpu']:.2f} |"]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.speed.open3d_ratio")
    ap.add_argument("--cases", default="", help="comma-separated names of CASES")
    ap.add_argument("--profile", default="", help="comma-separated cases to profile")
    ap.add_argument("--label", default=time.strftime("%Y-%m-%d"))
    ap.add_argument("--out", default=str(Path(__file__).parent / "results"))
    ap.add_argument("--o3d-path", default="", help="directory added to the children's path")
    ap.add_argument("--one", help=argparse.SUPPRESS)
    ap.add_argument("--prof", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.one:
        print(json.dumps(run_case(args.one, args.prof), default=float))
        return 0
    names = [c for c in args.cases.split(",") if c] or DEFAULT_CASES
    profiled = {c for c in args.profile.split(",") if c}
    env = {**os.environ, **_THREAD_ENV}
    if args.o3d_path:
        env["PYTHONPATH"] = os.pathsep.join(
            p for p in (env.get("PYTHONPATH", ""), args.o3d_path) if p)  # fmt: skip
    rows = []
    for name in names:
        cmd = [sys.executable, "-m", "benchmarks.speed.open3d_ratio", "--one", name]
        cmd += ["--prof"] if name in profiled else []
        done = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
        if done.returncode == 0:
            row = json.loads(done.stdout.strip().splitlines()[-1])
        else:
            row = {"name": name, "status": f"error: {(done.stderr.strip() or '?')[-300:]}"}
        print(json.dumps({k: row.get(k) for k in ("name", "cpu", "ratio", "load")}), flush=True)
        rows.append(row)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    stem = out / f"open3d-ratio-{args.label}"
    stem.with_suffix(".json").write_text(json.dumps(rows, indent=1, default=float))
    stem.with_suffix(".md").write_text(_markdown(rows, args.label))
    print(_markdown(rows, args.label))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
