import sys

from benchmarks.quality.ends import cases as ce
from benchmarks.quality.ends import ours as oe
from benchmarks.quality.ends import peers as pe
from benchmarks.quality.ends.ends_exp import end_variant
from benchmarks.quality.scores import Scorer
from service.core import SmoothingParams, smooth
from service.core.operator.build import build_operator

for k in sys.argv[1].split(","):
    c = ce.case(k)
    sc = Scorer(c)
    g = oe.geometry(c)
    (vv, vn), (vs, sn) = pe.vtk_best(c, sc)
    op = build_operator(g, SmoothingParams(lam=1.0))
    res = {}
    res["today"] = oe.oracle(c, sc, op)
    res["fixed"] = oe.oracle(c, sc, op, fix_boundary=True)
    res["zero"] = oe.oracle(c, sc, end_variant(op, "zero"))
    a_today = sc.quick(smooth(g, SmoothingParams()).points)
    a_fixed = sc.quick(smooth(g, SmoothingParams(fix_boundary=True)).points)
    print(
        f"{k:20s} vtk {vv:.3f}/{vs:.3f} "
        + " ".join(f"{m} {v / vv:.2f}/{s / vs:.2f}" for m, (v, s) in res.items())
        + f" | auto today {a_today[0] / vv:.2f}/{a_today[1] / vs:.2f}"
        + f" fixed {a_fixed[0] / vv:.2f}/{a_fixed[1] / vs:.2f}",
        flush=True,
    )
