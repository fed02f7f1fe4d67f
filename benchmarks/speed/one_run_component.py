"""The one-run Lanczos solver alone against Open3D's Laplacian x10 (issue 30, phase 1).

``python -m benchmarks.speed.one_run_component [--input torus:1000] [--keep-mib 1024]``

In one process (one thread): the default's system is prepared as ``smooth`` prepares it
(operator, data weights, normal frames: not timed), then the knee, lambda and the solution from
:func:`service.core.search.one_run.one_run` (CPU seconds, products), for the default (automatic
tau, knee) and for rms = 1.7 sigma (tau given), each result's RMS distance to the true surface,
and Open3D's ``filter_smooth_laplacian(number_of_iterations=10)`` on the same mesh. One JSON line.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from typing import Any

import numpy as np


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.speed.one_run_component")
    ap.add_argument("--input", default="torus:1000")
    ap.add_argument("--keep-mib", type=int, default=1024)
    args = ap.parse_args(argv)
    from threadpoolctl import threadpool_limits

    from benchmarks.speed.jobs import INPUTS, LEVELS
    from benchmarks.speed.open3d_ratio import _open3d, _quality
    from service.core import SmoothingParams
    from service.core.pipeline import plan_and_prepare
    from service.core.search.autotau import auto_tau
    from service.core.search.budget import free_weight, rms_to_tau
    from service.core.search.one_run import direct_cost, one_run
    from service.core.search.roots import newton_search
    from service.core.system.deviation import Deviation

    kind, _, arg = args.input.partition(":")
    g, sigma, truth = INPUTS[kind](arg)
    out: dict[str, Any] = {"input": args.input, "n": g.n, "load": [list(os.getloadavg())]}
    with threadpool_limits(1):
        _, pr = plan_and_prepare(g, SmoothingParams())
        s, frame = pr.system, pr.frame
        d = np.sqrt(s.d2)[:, None]
        M = s.M
        apply = lambda V: np.asarray(M @ (V / d)) / d  # noqa: E731
        c = s.r / d
        scale = None if pr.weights is None else pr.weights.tau_scale
        adjacency = pr.op.neighborhoods.adjacency
        tau0 = auto_tau(pr.geometry, pr.params, pr.fixed, adjacency, scale).tau
        tau_rms = rms_to_tau(LEVELS["peer"] * sigma, free_weight(pr.geometry, pr.fixed))
        for name, tau, knee in (("default", tau0, True), ("rms 1.7 sigma", tau_rms, False)):
            c0 = time.process_time()
            res = one_run(apply, c, d, tau / frame.phi_factor, s.lambda_floor(),
                          order=pr.params.order, knee=knee, keep_bytes=args.keep_mib * 2**20,
                          budget=direct_cost(s.size))  # fmt: skip
            E, factorized = res.E, 0
            if E is None:  # the cost model's choice: the factorized search from the run's lambda
                dev = Deviation(s, solver="cholmod", order=pr.params.order)
                t = res.tau
                found = newton_search(dev, dev.derivative, t, res.lam, dev.floor,
                                      max(s.lambda_ceiling(t), dev.floor), order=dev.order,
                                      propose=dev.local_root)  # fmt: skip
                E, factorized = dev.deviation(found.lam), dev.stats.factorizations
            cpu = time.process_time() - c0
            X = g.points.copy()
            X[~pr.fixed] = frame.back(pr.to_points(s.U0 + E))
            out[name] = {
                "cpu": cpu, "products": res.products, "steps": res.steps,
                "factorizations": factorized, "notes": res.notes,
                "knee_steps": res.knee_steps, "knee": res.knee is not None,
                "phi_over_tau": res.phi / res.tau, "bound": res.bound,
                "quality": _quality(X, truth, args.input), "load": list(os.getloadavg()),
            }  # fmt: skip
        peer = _open3d(g.points, g.faces)
    if peer is not None:
        out["open3d"] = {"cpu": peer["cpu"], **_quality(peer["points"], truth, args.input)}
        for name in ("default", "rms 1.7 sigma"):
            out[name]["ratio"] = out[name]["cpu"] / peer["cpu"]
    print(json.dumps(out, default=lambda x: None if isinstance(x, float) and math.isnan(x) else x))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
