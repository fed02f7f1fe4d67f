import sys
import time

import numpy as np

from benchmarks.quality.ends import cases as ce
from benchmarks.quality.ends import ours as oe
from service.core import SmoothingParams, smooth
from service.core.linalg import cache

BEFORE = {"ends": "pulled", "boundary": "ring"}
cases = [(k, {}) for k in sys.argv[1].split(",")] + [
    (k, {"displacement": "free"}) for k in sys.argv[2].split(",") if k
]
for k, kw in cases:
    g = oe.geometry(ce.case(k))
    a, b = [], []
    pa, pb = SmoothingParams(**kw), SmoothingParams(**kw, **BEFORE)
    smooth(g, pa)
    smooth(g, pb)  # warm-up
    for i in range(7):
        order = ((pa, a), (pb, b)) if i % 2 == 0 else ((pb, b), (pa, a))
        for p, acc in order:
            cache.clear()
            t = time.process_time()
            smooth(g, p)
            acc.append(time.process_time() - t)
    print(
        f"{k} {kw} after {np.median(a):.3f}s before {np.median(b):.3f}s "
        f"ratio {np.median(a) / np.median(b):.2f}",
        flush=True,
    )
