"""Tiled default against untiled default, 1M terrain clouds (issue 43).

``python -m benchmarks.tiles.default KIND N TILE_POINTS`` with KIND ``clean`` (2 cm height
noise), ``noisy`` (10 cm) or ``stray`` (2 cm and 0.3 % of the points thrown 1-5 m up or down).
Each run (untiled, then tiled) is a fresh process (``run`` sub-command) so that CPU seconds
(user + system of that process) and peak RSS are its own. Reported: the RMS of
``X_tiled - X_untiled`` over the untiled RMS displacement, both lambdas, outliers, CPU, peak
memory, the load. One JSON line per comparison in ``results/default.jsonl``.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks.tiles import terrain

OUT = Path(__file__).resolve().parent / "results" / "default.jsonl"
SIGMA = {"clean": 0.02, "noisy": 0.10, "stray": 0.02}


def points(kind: str, n: int) -> np.ndarray:
    """The terrain cloud of ``kind`` (module docstring), seeded."""
    P = terrain.cloud(n, sigma=SIGMA[kind])
    if kind == "stray":
        rng = np.random.default_rng(5)
        at = rng.choice(n, int(0.003 * n), replace=False)
        P[at, 2] += rng.uniform(1, 5, at.size) * rng.choice([-1.0, 1.0], at.size)
    return P


def run(kind: str, n: int, tile_points: int, out: str) -> None:
    """One run in this process; the points to ``out`` (.npy), the numbers to stdout."""
    from service.core import Geometry, SmoothingParams, smooth

    P = points(kind, n)
    before = resource.getrusage(resource.RUSAGE_SELF)
    params = SmoothingParams(tile_points=tile_points or None)
    res = smooth(Geometry(P), params)
    after = resource.getrusage(resource.RUSAGE_SELF)
    np.save(out, res.points)
    np.save(out + ".outliers.npy", res.outliers)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    tiles = res.tiles or {}
    print(json.dumps({"lam": res.lam, "cpu": cpu, "peak_mb": after.ru_maxrss / 1024,
                      "outliers": int(res.outliers.size), "sigma": res.sigma_estimate,
                      "halo_hops": tiles.get("halo_hops"),
                      "members": [t["points"] + t["halo"] for t in tiles.get("tiles", [])]}))


def _child(kind: str, n: int, tile_points: int, out: str) -> dict:
    cmd = ["nice", "-n", "5", sys.executable, "-m", "benchmarks.tiles.default", "run", kind,
           str(n), str(tile_points), out]
    done = subprocess.run(cmd, check=True, capture_output=True, text=True)
    return dict(json.loads(done.stdout.strip().splitlines()[-1]))


def main(argv: list[str]) -> None:
    if argv[0] == "run":
        run(argv[1], int(argv[2]), int(argv[3]), argv[4])
        return
    kind, n, tile_points = argv[0], int(argv[1]), int(argv[2])
    P = points(kind, n)
    base = f"/tmp/tiles-default-{kind}-{n}"
    untiled = _child(kind, n, 0, base + "-u.npy")
    tiled = _child(kind, n, tile_points, base + "-t.npy")
    U, X = np.load(base + "-u.npy"), np.load(base + "-t.npy")
    disp = float(np.sqrt(np.mean(np.sum((U - P) ** 2, axis=1))))
    diff = float(np.sqrt(np.mean(np.sum((X - U) ** 2, axis=1))))
    ou, ot = (np.load(base + s + ".npy.outliers.npy") for s in ("-u", "-t"))
    row = {"kind": kind, "n": n, "tile_points": tile_points, "diff": diff / max(disp, 1e-300),
           "outliers_xor": int(np.setxor1d(ou, ot).size), "untiled": untiled, "tiled": tiled,
           "cpu_ratio": tiled["cpu"] / untiled["cpu"],
           "peak_ratio": tiled["peak_mb"] / untiled["peak_mb"],
           "load": os.getloadavg()[0], "when": time.strftime("%Y-%m-%d %H:%M:%S")}
    print(json.dumps(row), flush=True)
    with open(OUT, "a") as fh:
        fh.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main(sys.argv[1:])
