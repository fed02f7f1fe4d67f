"""Issue 30 item 3: CPU of the stages around the solve, one process per tree and input.

``PYTHONPATH=<tree> python -m benchmarks.speed.stage_cpu <case> [--label L] [--out FILE]``

``case`` is a name of :data:`benchmarks.speed.open3d_ratio.CASES` (``"1M default"``,
``"164K default"``). The input is built as there; the compiled kernels are warmed first on a
60,000-vertex torus (numba caches per file path: the first run of a fresh tree compiles, the
stage CPU must not count that); then ``service.core.smooth`` runs once under :mod:`cProfile`
(timer ``time.process_time``, one thread) and its cumulative CPU is grouped by the stages of
:data:`benchmarks.speed.open3d_ratio.STAGES`. Printed as one JSON line (appended to ``--out``)
with the load average before and after and a SHA-256 of the output points, so that two trees
can be checked to give the same output bit for bit. Run it with one thread everywhere
(``GEOSMOOTH_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 NUMBA_NUM_THREADS=1``, as
:mod:`benchmarks.speed.open3d_ratio` sets for its children).
"""

from __future__ import annotations

import argparse
import cProfile
import hashlib
import json
import os
import sys
import time
from typing import Any

import numpy as np

from benchmarks.speed.open3d_ratio import CASES, STAGES


def measure(name: str, label: str) -> dict[str, Any]:
    """Warm up, then profile ``smooth`` on case ``name``; CPU per stage and the output hash."""
    from threadpoolctl import threadpool_limits

    import service.core.linalg.solver  # noqa: F401  (CHOLMOD's pools exist before the limit)
    from benchmarks.speed.jobs import INPUTS
    from service.core import SmoothingParams, smooth

    inp, extra = CASES[name]
    assert not extra, "stage CPU is measured on the default path"
    kind, _, arg = inp.partition(":")
    g = INPUTS[kind](arg)[0]
    with threadpool_limits(1):
        smooth(INPUTS["torus"]("450")[0], SmoothingParams())  # 67,500 vertices: every kernel
        prof = cProfile.Profile(time.process_time)
        load0 = [round(x, 2) for x in os.getloadavg()]
        c0 = time.process_time()
        prof.enable()
        res = smooth(g, SmoothingParams())
        prof.disable()
        cpu = time.process_time() - c0
    import pstats

    stages: dict[str, float] = {}
    for (path, _, fn), (_, _, _, cumulative, _) in pstats.Stats(prof).stats.items():  # type: ignore[attr-defined]
        for stage, (suffix, names) in STAGES.items():
            if fn in names and path.endswith(suffix) and "service" in path:
                stages[stage] = stages.get(stage, 0.0) + cumulative
    return {
        "label": label, "case": name, "n": g.n, "cpu_total": round(cpu, 2),
        "load": [load0, [round(x, 2) for x in os.getloadavg()]],
        "stages": {k: round(v, 2) for k, v in sorted(stages.items())},
        "points_sha256": hashlib.sha256(np.ascontiguousarray(res.points).tobytes()).hexdigest(),
        "lam": res.lam, "phi": res.phi, "matvecs": res.matvecs,
    }  # fmt: skip


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("case", choices=sorted(CASES))
    ap.add_argument("--label", default="")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    row = json.dumps(measure(args.case, args.label))
    print(row)
    if args.out:
        with open(args.out, "a") as fh:
            fh.write(row + "\n")


if __name__ == "__main__":
    main(sys.argv[1:])
