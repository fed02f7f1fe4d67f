"""``python -m benchmarks.quality.noise_matrix --half calibration|test [--tag T]``.

Issue 37 item 5: the default (no smoothing parameter) on the noise matrix of one half — the
shapes whose isotropic-noise family is in that half (:data:`~.families.SPLIT`), at 0.05, 0.1,
0.25, 0.5 and 1 edge length of isotropic noise — against fixed Taubin (lambda 0.5, mu -0.53,
10 and 50 iterations, :func:`~.issue31.taubin`) and Open3D's ``filter_smooth_laplacian`` x10
(meshes), errors against the ground truth as fractions of the input's (vertex / distance to
the true surface), and sigma^ / sigma. One process per run; CPU seconds of the default.
Writes ``results/noise-matrix-<half>-<tag>-<date>.{json,md}``.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.quality.cases import make_case
from benchmarks.quality.families import SPLIT
from benchmarks.quality.issue31 import TAUBIN_ITERATIONS, taubin
from benchmarks.quality.ours import geometry_of
from benchmarks.quality.scores import Scorer

RESULTS = Path(__file__).resolve().parent / "results"
LEVELS = (0.05, 0.1, 0.25, 0.5, 1.0)


def keys(half: str, levels: tuple[float, ...] = LEVELS) -> list[str]:
    shapes = sorted(s for (s, nz), h in SPLIT.items() if nz == "iso" and h == half)
    return [f"{s}/iso-{lv:g}" for s in shapes for lv in levels]


def _open3d(points: np.ndarray, faces: np.ndarray) -> np.ndarray | None:
    try:
        import open3d as o3d
    except ImportError:
        return None
    tri = o3d.utility.Vector3iVector(faces.astype(np.int32))
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(points), tri)
    return np.asarray(mesh.filter_smooth_laplacian(number_of_iterations=10).vertices)


def run_case(key: str) -> dict[str, Any]:
    from service.core import smooth
    from service.core.params import SmoothingParams

    case = make_case(key)
    sc = Scorer(case)
    t0 = time.process_time()
    res = smooth(geometry_of(case), SmoothingParams())
    cpu = time.process_time() - t0
    sigma_hat = res.report().get("sigma_estimate")
    out: dict[str, Any] = {"key": key, "n": case.n, "cpu": cpu, "default": sc.quick(res.points),
                           "sigma_ratio": (sigma_hat or 0.0) / case.sigma}  # fmt: skip
    for it in TAUBIN_ITERATIONS:
        try:
            out[f"taubin{it}"] = sc.quick(taubin(case, it))
        except RuntimeError as exc:
            out[f"taubin{it}"] = str(exc)
    if case.shape.faces is not None and case.shape.points.shape[1] == 3:
        X = _open3d(case.points, case.shape.faces)
        if X is not None:
            out["open3d"] = sc.quick(X)
    return out


def render(rows: list[dict[str, Any]]) -> str:
    lines = ["| case | sigma^/sigma | default v / s | Taubin x10 v / s | x50 v / s | Open3D x10 "
             "v / s | default s / best Taubin s | CPU s |", "|---|---|---|---|---|---|---|---|"]
    ratios = []
    for r in rows:
        tb = [r[f"taubin{it}"] for it in TAUBIN_ITERATIONS if isinstance(r.get(f"taubin{it}"),
                                                                         list | tuple)]
        best = min(t[1] for t in tb) if tb else float("nan")
        ratio = r["default"][1] / best if tb else float("nan")
        ratios.append(ratio)
        o3 = r.get("open3d")
        cells = [f"{r['key']}", f"{r['sigma_ratio']:.2f}",
                 f"{r['default'][0]:.3f} / {r['default'][1]:.3f}"]
        cells += [f"{t[0]:.3f} / {t[1]:.3f}" if isinstance(t, list | tuple) else "-"
                  for t in (r.get("taubin10"), r.get("taubin50"))]
        cells += [f"{o3[0]:.3f} / {o3[1]:.3f}" if o3 else "-", f"{ratio:.2f}", f"{r['cpu']:.2f}"]
        lines.append("| " + " | ".join(cells) + " |")
    arr = np.array([x for x in ratios if np.isfinite(x)])
    if arr.size:
        lines.append(f"\nDefault's surface error / best fixed Taubin's: median "
                     f"{np.median(arr):.2f}, worst {arr.max():.2f}, > 1 on "
                     f"{int(np.sum(arr > 1.0))} of {arr.size}.")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.quality.noise_matrix")
    ap.add_argument("--half", default="calibration")
    ap.add_argument("--tag", default="run")
    ap.add_argument("--out", type=Path, default=RESULTS)
    a = ap.parse_args(argv)
    rows = []
    for key in keys(a.half):
        rows.append(run_case(key))
        print(key, rows[-1]["default"], file=sys.stderr, flush=True)
    stem = f"noise-matrix-{a.half}-{a.tag}-{dt.date.today()}"
    (a.out / f"{stem}.json").write_text(json.dumps(rows, indent=1))
    (a.out / f"{stem}.md").write_text(f"# noise matrix, {a.half}, {a.tag}\n\n" + render(rows))
    print(render(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
