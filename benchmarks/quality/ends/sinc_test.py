import sys

import service.core.search.polyfilter as pf
from benchmarks.quality.ends import cases as ce
from benchmarks.quality.ends import ours as oe
from benchmarks.quality.ends import peers as pe
from benchmarks.quality.scores import Scorer

for k in sys.argv[1].split(","):
    c = ce.case(k)
    sc = Scorer(c)
    (vv, vn), (vs, sn) = pe.vtk_best(c, sc)
    row = [f"{k:20s} vtk {vv:.3f}/{vs:.3f}"]
    for r in (0.0, 2.0):
        pf.RESOLUTION = r
        v, s = oe.oracle(c, sc, method="windowed-sinc")
        va, sa = oe.auto(c, sc, method="windowed-sinc")
        row.append(f"res{r:g} oracle {v / vv:.2f}/{s / vs:.2f} auto {va / vv:.2f}/{sa / vs:.2f}")
    print(" ".join(row), flush=True)
