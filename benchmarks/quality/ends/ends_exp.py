import sys

import numpy as np

from benchmarks.quality.ends import cases as ce
from benchmarks.quality.ends import ours as oe
from benchmarks.quality.ends import peers as pe
from benchmarks.quality.scores import Scorer
from service.core import SmoothingParams
from service.core.operator.build import build_operator


def end_variant(op, how):
    L = op.L.tolil()
    adj = op.neighborhoods.adjacency
    deg = np.diff(adj.indptr)
    for i in np.flatnonzero(deg == 1):
        j = adj.indices[adj.indptr[i]]
        if how == "zero":
            L[i, :] = 0
        elif how == "second":
            ks = [k for k in adj.indices[adj.indptr[j] : adj.indptr[j + 1]] if k != i]
            if len(ks) == 1:
                L[i, :] = 0
                L[i, i] = 0.5
                L[i, j] = -1.0
                L[i, ks[0]] = 0.5
    return oe.with_laplacian(op, L.tocsr())


if __name__ == "__main__":
    for k in sys.argv[1].split(","):
        c = ce.case(k)
        sc = Scorer(c)
        g = oe.geometry(c)
        (vv, vn), (vs, sn) = pe.vtk_best(c, sc)
        row = [f"{k:20s} vtk {vv:.3f}/{vs:.3f} [{vn}]"]
        for order in (2, 3):
            kw = {"order": order}
            op = build_operator(g, SmoothingParams(lam=1.0, **kw))
            for how in ("today", "fixed", "zero", "second"):
                if how == "fixed":
                    v, s = oe.oracle(c, sc, op, fix_boundary=True, **kw)
                else:
                    v, s = oe.oracle(c, sc, op if how == "today" else end_variant(op, how), **kw)
                row.append(f"o{order} {how} {v:.3f}/{s:.3f} ({v / vv:.2f}x/{s / vs:.2f}x)")
        print("\n   ".join(row), flush=True)
