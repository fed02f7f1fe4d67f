"""The full version of the suite's high-dimensional default-path check (issue 34).

``tests/core/test_default_safe.py::test_high_dimensional_cloud_uses_free_displacement_and_meets_tau``
smooths 50 random points in 40-D with the defaults (under a second). The check it was sized
down from used 300-D, which took 44 s of CPU on the project's 2-core machine (4.6 s in 100-D):
the default path's cost grows with about the square of the dimension. This runs that check
at every dimension given and prints the CPU seconds, so the growth can be followed::

    python -m benchmarks.high_dimension            # 10, 40, 100, 300
    python -m benchmarks.high_dimension 300 600
"""

from __future__ import annotations

import sys
import time

import numpy as np

from service.core import Geometry, SmoothingParams, smooth

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    dims = [int(a) for a in (sys.argv[1:] if argv is None else argv)] or [10, 40, 100, 300]
    print("| dim | points | displacement | tau met | CPU s |")
    print("| ---: | ---: | --- | --- | ---: |")
    for dim in dims:
        P = np.random.default_rng(0).normal(size=(50, dim))
        start = time.process_time()
        res = smooth(Geometry(P), SmoothingParams())
        cpu = time.process_time() - start
        met = res.tau is None or abs(np.sum((res.points - P) ** 2) - res.tau) <= 1e-3 * res.tau
        print(f"| {dim} | 50 | {res.displacement} | {met} | {cpu:.2f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
