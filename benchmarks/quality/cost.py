"""Cost of the default (no smoothing parameter) on benchmark cases, cold, for comparing trees.

Each run is what a new input pays: the operator and analysis caches are cleared and the points are
a fresh array (the noise estimate is remembered per array). CPU seconds (all threads), median of
``--repeat`` runs in this process after one warm-up run (numba). Compare two trees by running this
module with each tree first on ``PYTHONPATH``, interleaved, several times, and take the median of
the per-process medians (issue 21: ``results/cost-2026-11-26.md``)::

    PYTHONPATH=<tree> python -m benchmarks.quality.cost sphere-10K/aniso-0.5 cloud-bunny/aniso-0.5
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

from benchmarks.quality.cases import make_case
from benchmarks.quality.ours import geometry_of
from service.core import Geometry, SmoothingParams, smooth
from service.core.linalg import cache


def cold_seconds(key: str, repeat: int = 3) -> float:
    """Median CPU seconds of the default on case ``key``, each run on a fresh input."""
    g = geometry_of(make_case(key))

    def fresh() -> Geometry:
        return Geometry(g.points.copy(), faces=g.faces, edges=g.edges)

    smooth(fresh(), SmoothingParams())  # warm-up: compiled kernels
    times = []
    for _ in range(repeat):
        cache.clear()
        h = fresh()
        t0 = time.process_time()
        smooth(h, SmoothingParams())
        times.append(time.process_time() - t0)
    return statistics.median(times)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cases", nargs="+", help="case keys, e.g. torus-40K/aniso-0.5")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    print(json.dumps({key: round(cold_seconds(key, args.repeat), 3) for key in args.cases}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
