"""1M torus, default path: CPU seconds per stage (cProfile timed by ``time.process_time``, one
thread) -- issue 22's stage breakdown.

``PYTHONPATH=<tree> python benchmarks/speed/stages.py <label>`` prints one JSON line.
"""

from __future__ import annotations

import cProfile
import json
import pstats
import sys
import time

import numpy as np
from threadpoolctl import threadpool_limits

import service.core.linalg.solver  # noqa: F401  (loads CHOLMOD's pools before the limit)
from benchmarks.speed.jobs import _torus
from service.core import SmoothingParams, smooth

STAGES = {
    "mesh_neighborhoods": "1-ring build",
    "build_operator": "operator (all)",
    "normal_mode": "normal-displacement system",
    "choose_and_solve": "automatic lambda and solution",
    "find_lambda": "lambda search + solves",
    "diagnostics": "diagnostics + shape checks",
    "factor": "CHOLMOD factorizations",
    "analyze": "CHOLMOD analysis",
    "matvec": "products",
}


def main() -> None:
    threadpool_limits(1)
    g, _, P = _torus(1000)
    prof = cProfile.Profile(time.process_time)
    c0 = time.process_time()
    prof.enable()
    res = smooth(g, SmoothingParams())
    prof.disable()
    cpu = time.process_time() - c0
    out: dict[str, float] = {}
    for (_, _, fn), (_, _, _, cumulative, _) in pstats.Stats(prof).stats.items():  # type: ignore[attr-defined]
        if fn in STAGES:
            out[STAGES[fn]] = out.get(STAGES[fn], 0.0) + cumulative
    err = float(np.sqrt(np.mean(np.sum((res.points - P) ** 2, 1))))
    print(json.dumps({
        "tree": sys.argv[1] if len(sys.argv) > 1 else "", "cpu_total": cpu, "solver": res.solver,
        "matvecs": res.matvecs, "factorizations": res.factorizations, "err": err,
        "stages_cpu": {k: round(v, 2) for k, v in sorted(out.items())},
    }))  # fmt: skip


if __name__ == "__main__":
    main()
