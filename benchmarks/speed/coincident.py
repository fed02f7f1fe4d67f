"""Coincident points (issue 42 item 5, issue 39): CPU seconds of the default on a cloud of
``m`` copies of one point, or of a 20,000-point noisy sphere plus ``m`` copies of one of its
points, in this process (one thread, ``time.process_time``).

``PYTHONPATH=<tree> python -m benchmarks.speed.coincident <m> [all|mixed]`` prints one JSON line.
"""

from __future__ import annotations

import json
import os
import sys
import time

import numpy as np
from threadpoolctl import threadpool_limits


def main() -> None:
    from service.core import SmoothingParams, smooth
    from service.core.geometry import Geometry

    m, mode = int(sys.argv[1]), sys.argv[2] if len(sys.argv) > 2 else "all"
    if mode == "all":
        P = np.ones((m, 3))
    else:
        rng = np.random.default_rng(0)
        Q = rng.normal(size=(20000, 3))
        Q /= np.linalg.norm(Q, axis=1)[:, None]
        Q += 0.01 * rng.normal(size=Q.shape)
        P = np.vstack([Q, np.repeat(Q[:1], m, 0)])
    load = os.getloadavg()[0]
    with threadpool_limits(1):
        c0 = time.process_time()
        res = smooth(Geometry(P), SmoothingParams())
        cpu = time.process_time() - c0
    row = {"copies": m, "mode": mode, "n": P.shape[0], "cpu": round(cpu, 2),
           "load": round(load, 1), "solver": res.solver, "products": res.matvecs}  # fmt: skip
    print(json.dumps(row))


if __name__ == "__main__":
    main()
