import sys

import numpy as np

from benchmarks.quality import peers as qp
from benchmarks.quality.ends import cases as ce
from benchmarks.quality.ends import ours as oe
from benchmarks.quality.scores import Scorer


def peer(c, sc, name):
    p = next(x for x in qp.QUALITY_PEERS if x.name == name)
    bv = bs = np.inf
    err = None
    for s in p.grid(c.shape, False):
        try:
            X = (
                qp.run_isolated(p.run, c.points, c.shape, s)
                if p.isolated
                else p.run(c.points, c.shape, s)
            )
        except Exception as e:
            err = str(e)[:60]
            break
        v, s2 = sc.quick(X)
        bv = min(bv, v)
        bs = min(bs, s2)
    return bv, bs, err


modes = {
    "default": {},
    "k12": {"k": 12},
    "k30": {"k": 30},
    "knn20": {"neighborhood": "knn"},
    "o3": {"order": 3},
    "free": {"displacement": "free"},
}
for k in sys.argv[1].split(","):
    c = ce.case(k)
    sc = Scorer(c)
    row = [k]
    for name in ("Open3D cloud MLS", "PyMeshLab APSS", "PyMeshLab RIMLS"):
        v, s, e = peer(c, sc, name)
        row.append(f"{name.split()[-1]} {v:.3f}/{s:.3f}" + (f" ({e})" if e else ""))
    for m, kw in modes.items():
        v, s = oe.oracle(c, sc, **kw)
        row.append(f"{m} {v:.3f}/{s:.3f}")
    print(" | ".join(row), flush=True)
