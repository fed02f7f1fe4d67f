import sys

import numpy as np

from benchmarks.quality.ends import cases as ce
from benchmarks.quality.ends import ours as oe
from benchmarks.quality.ends import peers as pe
from benchmarks.quality.scores import Scorer
from service.core import SmoothingParams
from service.core.operator.build import build_operator


def boundary_edges(F, n):
    E = np.sort(np.vstack([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    u, cnt = np.unique(E, axis=0, return_counts=True)
    return u[cnt == 1]


def bvariant(op, F, how):
    L = op.L.tolil()
    n = L.shape[0]
    be = boundary_edges(F, n)
    bn = {}
    for a, b in be:
        bn.setdefault(a, []).append(b)
        bn.setdefault(b, []).append(a)
    for i, js in bn.items():
        L[i, :] = 0
        if how == "curve":
            L[i, i] = 1.0
            for j in js:
                L[i, j] = -1.0 / len(js)
    return oe.with_laplacian(op, L.tocsr())


for k in sys.argv[1].split(","):
    c = ce.case(k)
    sc = Scorer(c)
    g = oe.geometry(c)
    (tv, tn), (ts, tsn) = pe.taubin_best(c, sc)
    row = [f"{k:22s} taubin {tv:.3f}/{ts:.3f} [{tn}]"]
    for disp in ("normal", "free"):
        kw = {"displacement": disp}
        op = build_operator(g, SmoothingParams(lam=1.0, **kw))
        for how in ("today", "fixed", "curve", "zero"):
            if how == "fixed":
                v, s = oe.oracle(c, sc, op, fix_boundary=True, **kw)
            else:
                v, s = oe.oracle(
                    c, sc, op if how == "today" else bvariant(op, c.shape.faces, how), **kw
                )
            row.append(f"{disp} {how} {v:.3f}/{s:.3f} ({v / tv:.2f}x/{s / ts:.2f}x)")
    print("\n   ".join(row), flush=True)
