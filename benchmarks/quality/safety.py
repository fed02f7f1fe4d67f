"""The default on noisy, noise-free and over-smoothed inputs (issue 20): what it changes where
there is no noise, how much it improves where there is, and whether the shape checks tell the
truth.

``python -m benchmarks.quality.safety OUT.json`` runs the tree on ``PYTHONPATH`` (so the same
file measures a former tree too: ``PYTHONPATH=/path/to/old:.``). Per case:

* **noisy** (``cases.make_case``) and **noised real files** (the shared files plus isotropic
  noise of 0.25 h in their non-flat coordinates, fixed seed): the default's RMS vertex error and
  distance to the truth as fractions of the input's; its warnings. A shape warning on a result
  better than its input in both is a **false alarm**.
* **noise-free** (the benchmark's clean shapes, the shared files as they are): the change the
  default made (RMS deviation over the mean spacing, length/area/volume change), whether it said
  "no noise found".
* **over-smoothed** (``rms = 2 h`` and ``rms = 4 h`` given): a result farther from the true
  surface than its input with no shape warning is a **miss**.

Split: cases whose key hashes even are the calibration half (thresholds chosen on them), the
others the test half (reported); the JSON carries the half of every case.
"""

from __future__ import annotations

import json
import sys
import time
import zlib
from typing import Any

import numpy as np

from benchmarks.quality.cases import make_case, make_shape
from benchmarks.shapes import data_dir
from service.core import Geometry, SmoothingParams, smooth

SHAPES = ["sphere-2.5K", "torus-5.8K", "box", "fandisk", "spot", "circle-2d", "trefoil-3d",
          "cloud-sphere", "network-2d", "network-3d", "cloud-fandisk"]
NOISES = ["normal-0.1", "iso-0.25", "aniso-0.5"]
FILES = ["featuretype.ply", "ne_110m_coastline.obj", "ne_110m_coastline.geojson", "wrench.dxf",
         "fandisk.obj", "spot.obj", "bunny.ply", "bun_zipper_res4.ply", "korita-zbevnica.gpx",
         "turbineblade.ply", "blackVase_decimated.ply"]
DATA = f"{data_dir()}/"
SHAPE_WORDS = ("destroyed", "flattened", "shrank", "turned over", "folded over")


def half(key: str) -> str:
    return "calibration" if zlib.crc32(key.encode()) % 2 == 0 else "test"


def _spacing(g: Geometry) -> float:
    from service.core.info import mean_spacing

    return float(mean_spacing(g))


def _shape_warned(warnings: list[str]) -> bool:
    return any(any(w in x for w in SHAPE_WORDS) for x in warnings)


def _run(g: Geometry, **kw: Any) -> tuple[np.ndarray, dict[str, Any]]:
    t = time.perf_counter()
    try:
        r = smooth(g, SmoothingParams(**kw))
    except Exception as exc:
        return g.points, {"error": f"{type(exc).__name__}: {exc}"[:300]}
    rep = r.report()
    return r.points, {
        "seconds": time.perf_counter() - t,
        "sigma": rep.get("sigma_estimate"),
        "noise_found": rep.get("noise_found"),
        "tau": rep.get("tau"),
        "warnings": rep.get("warnings", []),
        "shape_warned": bool(rep["shape_warnings"]) if "shape_warnings" in rep
        else _shape_warned(rep.get("warnings", [])),
        "area_change": rep.get("area_change"),
        "volume_change": rep.get("volume_change"),
        "flipped_faces": rep.get("flipped_faces"),
        "rms_deviation": rep.get("rms_deviation"),
    }


def _errors(X: np.ndarray, P: np.ndarray, truth: np.ndarray, dist: Any) -> dict[str, float]:
    e0 = float(np.sqrt(np.mean(np.sum((P - truth) ** 2, axis=1))))
    e1 = float(np.sqrt(np.mean(np.sum((X - truth) ** 2, axis=1))))
    out = {"vertex": e1 / e0 if e0 > 0 else float("nan")}
    if dist is not None:
        s0 = float(np.sqrt(np.mean(dist(P) ** 2)))
        out["surface"] = float(np.sqrt(np.mean(dist(X) ** 2))) / s0 if s0 > 0 else float("nan")
    return out


def _file(name: str) -> Geometry:
    from service.io import read_geometry

    return read_geometry(DATA + name).geometry  # type: ignore[no-any-return]


def _noised(g: Geometry, key: str) -> Geometry:
    rng = np.random.default_rng(zlib.crc32(key.encode()))
    h = _spacing(g)
    live = np.ptp(g.points, axis=0) > 0
    P = g.points + 0.25 * h * rng.normal(size=g.points.shape) * live
    return Geometry(P, faces=g.faces, edges=g.edges)


def main(out: str) -> None:
    rows: list[dict[str, Any]] = []

    def add(row: dict[str, Any]) -> None:
        rows.append(row)
        print(json.dumps({k: v for k, v in row.items() if k != "warnings"})[:300], flush=True)

    for shape_key in SHAPES:
        sh = make_shape(shape_key)
        clean = Geometry(sh.points, faces=sh.faces, edges=sh.edges)
        X, info = _run(clean)
        add({"kind": "noise-free", "key": shape_key, "half": half(shape_key), **info,
             "change_h": float(np.sqrt(np.mean(np.sum((X - sh.points) ** 2, axis=1)))) / sh.h})
        for nz in NOISES:
            c = make_case(f"{shape_key}/{nz}")
            g = Geometry(c.points, faces=sh.faces, edges=sh.edges)
            X, info = _run(g)
            add({"kind": "noisy", "key": c.key, "half": half(c.key), **info,
                 **_errors(X, c.points, sh.points, sh.distance)})
            for level in (2.0, 4.0):
                X, info = _run(g, rms=level * sh.h)
                add({"kind": "over-smoothed", "key": f"{c.key}@rms{level:g}h",
                     "half": half(c.key), **info,
                     **_errors(X, c.points, sh.points, sh.distance)})
    for name in FILES:
        try:
            g = _file(name)
        except Exception as exc:
            add({"kind": "noise-free", "key": name, "error": str(exc)})
            continue
        h = _spacing(g)
        X, info = _run(g)
        add({"kind": "noise-free", "key": name, "half": half(name), **info,
             "change_h": float(np.sqrt(np.mean(np.sum((X - g.points) ** 2, axis=1)))) / h})
        noisy = _noised(g, name)
        X, info = _run(noisy)
        add({"kind": "noised-file", "key": name + "+0.25h", "half": half(name), **info,
             **_errors(X, noisy.points, g.points, None)})
    with open(out, "w") as f:
        json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main(sys.argv[1])
