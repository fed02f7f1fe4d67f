"""The windowed-sinc's degree at a budget (issue 39 item 5): CPU seconds, products, the degree
reached and the surface error, one input in this process (one thread).

``PYTHONPATH=<tree> python -m benchmarks.speed.sinc_degree <input> [rms in sigmas]`` (inputs as
:mod:`benchmarks.speed.jobs` names them, e.g. ``torus:1000``; default 1.7 sigma, the "peer"
level; the noise's own 3-D RMS is 1.732) prints one JSON line, with Open3D's
``filter_smooth_laplacian`` x10 on the same mesh in the same process (median CPU of 3) and the
ratio.
"""

from __future__ import annotations

import json
import os
import sys
import time
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits


def main() -> None:
    from benchmarks.speed.jobs import INPUTS, LEVELS
    from benchmarks.speed.open3d_ratio import _open3d, surface_distance
    from service.core import SmoothingParams, smooth
    from service.core.search import polyfilter

    inp = sys.argv[1]
    level = float(sys.argv[2]) if len(sys.argv) > 2 else LEVELS["peer"]
    kind, _, arg = inp.partition(":")
    g, sigma, _ = INPUTS[kind](arg)
    degrees: list[int] = []
    band = polyfilter._band

    def counted(*args: Any) -> Any:
        degrees.append(args[3])
        return band(*args)

    polyfilter._band = counted  # type: ignore[assignment]
    load = os.getloadavg()[0]
    with threadpool_limits(1):
        c0 = time.process_time()
        res = smooth(g, SmoothingParams(rms=level * sigma, method="windowed-sinc"))
        cpu = time.process_time() - c0
        peer = _open3d(g.points, g.faces) if g.faces is not None else None
    err = lambda X: float(np.sqrt(np.mean(surface_distance(X, inp) ** 2)))  # noqa: E731
    row = {"input": inp, "n": g.n, "rms_sigmas": level, "cpu": round(cpu, 2),
           "load": round(load, 1), "products": res.matvecs, "degrees": degrees,
           "surface_error": err(res.points), "input_error": err(g.points),
           "converged": bool(res.converged)}  # fmt: skip
    if peer is not None:
        row.update(open3d_cpu=peer["cpu"], ratio=cpu / peer["cpu"],
                   open3d_error=err(peer["points"]))  # fmt: skip
    print(json.dumps(row))


if __name__ == "__main__":
    main()
