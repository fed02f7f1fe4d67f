"""Stitched equals untiled: ``python -m benchmarks.tiles.equality {cloud,mesh} N T1 T2 ...``.

The untiled run chooses tau automatically; the tiled runs (``T`` tiles: ``tile_points =
ceil(N / T)``) are given that tau. Reported per run: seconds, the RMS difference over the RMS
displacement of the untiled run, ``|sum phi_t - tau| / tau`` (phi recomputed from the stitched
points), rounds, halo, points per tile with halo. One JSON line per run is appended to
``benchmarks/tiles/results/equality.jsonl``.
"""

from __future__ import annotations

import json
import math
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks.tiles import terrain
from service.core import Geometry, SmoothingParams
from service.core.pipeline import smooth_one as smooth_untiled
from service.core.tiles import smooth_tiled

OUT = Path(__file__).resolve().parent / "results" / "equality.jsonl"


def _geometry(kind: str, n: int) -> Geometry:
    if kind == "cloud":
        return Geometry(terrain.cloud(n))
    P, F = terrain.mesh(round(math.sqrt(n)))
    return Geometry(P, faces=F)


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _emit(row: dict) -> None:
    row.update(load=os.getloadavg()[0], when=time.strftime("%Y-%m-%d %H:%M:%S"))
    print(json.dumps(row), flush=True)
    with open(OUT, "a") as fh:
        fh.write(json.dumps(row) + "\n")


def main(argv: list[str]) -> None:
    kind, n, counts = argv[0], int(argv[1]), [int(t) for t in argv[2:]]
    g = _geometry(kind, n)
    P = g.points
    t0 = time.perf_counter()
    ref = smooth_untiled(g, SmoothingParams())
    untiled_s = time.perf_counter() - t0
    tau = float(ref.tau)  # type: ignore[arg-type]
    disp = float(np.sqrt(np.mean(np.sum((ref.points - P) ** 2, axis=1))))
    _emit({"kind": kind, "n": g.n, "tiles": 1, "seconds": untiled_s, "tau": tau,
           "lam": ref.lam, "phi_rel": abs(ref.phi - tau) / tau, "rms_disp": disp,
           "factorizations": ref.factorizations, "solver": ref.solver,
           "peak_rss_mb": _rss_mb()})  # fmt: skip
    for count in counts:
        t0 = time.perf_counter()
        tiled = smooth_tiled(g, SmoothingParams(tau=tau), math.ceil(g.n / count))
        seconds = time.perf_counter() - t0
        X = tiled.result.points
        diff = float(np.sqrt(np.mean(np.sum((X - ref.points) ** 2, axis=1))))
        phi = float(np.sum((X - P) ** 2))
        _emit({"kind": kind, "n": g.n, "tiles": len(tiled.tiles), "seconds": seconds,
               "tau": tau, "lam": tiled.result.lam, "rms_diff_over_disp": diff / disp,
               "phi_rel": abs(phi - tau) / tau, "rounds": tiled.rounds, "halo_hops": tiled.hops,
               "hop_length": tiled.hop_length,
               "tile_points_with_halo": [t.points + t.halo for t in tiled.tiles],
               "tile_seconds": [round(t.seconds, 2) for t in tiled.tiles],
               "factorizations": tiled.result.factorizations,
               "peak_rss_mb": _rss_mb()})  # fmt: skip


if __name__ == "__main__":
    main(sys.argv[1:])
