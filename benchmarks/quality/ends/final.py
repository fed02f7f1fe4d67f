"""Before/after tables for issue 21 items 4 (curves, grids): ours at the oracle lambda and at the
automatic tau, before (ends='pulled', boundary='ring' = the code before this change) and after
(defaults), against VTK's windowed-sinc / PyMeshLab's Taubin swept over their parameters."""

import json
import sys
import time

import numpy as np

from benchmarks.quality.ends import cases as ce
from benchmarks.quality.ends import ours as oe
from benchmarks.quality.ends import peers as pe
from benchmarks.quality.scores import Scorer
from service.core import SmoothingParams, smooth

BEFORE = {"ends": "pulled", "boundary": "ring"}


def cpu(g, p):
    ts = []
    for _ in range(3):
        t = time.process_time()
        smooth(g, p)
        ts.append(time.process_time() - t)
    return float(np.median(ts))


out = []
for k in sys.argv[2].split(","):
    c = ce.case(k)
    sc = Scorer(c)
    g = oe.geometry(c)
    row = {"case": k, "half": sys.argv[1]}
    if c.shape.faces is None:
        (pv, pn), (ps, psn) = pe.vtk_best(c, sc)
        row["peer"] = "VTK sinc"
        modes = {"default": {}}
    else:
        (pv, pn), (ps, psn) = pe.taubin_best(c, sc)
        row["peer"] = "Taubin"
        (vv, _), (vs, _) = pe.vtk_best(c, sc)
        row["vtk"] = [vv, vs]
        modes = {"default": {}, "free": {"displacement": "free"}}
    row["peer_best"] = [pv, ps]
    for m, kw in modes.items():
        for tag, extra in (("before", BEFORE), ("after", {})):
            row[f"{m} oracle {tag}"] = list(oe.oracle(c, sc, **kw, **extra))
            row[f"{m} auto {tag}"] = list(oe.auto(c, sc, **kw, **extra))
    row["cost after/before"] = cpu(g, SmoothingParams()) / cpu(g, SmoothingParams(**BEFORE))
    out.append(row)
    print(json.dumps(row), flush=True)
