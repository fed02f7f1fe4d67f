import scipy.sparse as sp

from benchmarks.quality.sweep import lambda_oracle
from service.core import Geometry, SmoothingParams, smooth
from service.core.operator.build import SmoothingOperator, build_operator


def geometry(case):
    return Geometry(case.points, faces=case.shape.faces, edges=case.shape.edges)


def with_laplacian(op, L):
    return SmoothingOperator(
        sp.csr_matrix(L), op.neighborhoods, op.scheme, op.frame, op.key, op.timings
    )


def oracle(case, sc, op=None, **kw):
    g = geometry(case)
    memo = {}
    if op is None:
        op = build_operator(g, SmoothingParams(lam=1.0, **kw))

    def ev(lam):
        try:
            r = smooth(g, SmoothingParams(lam=lam, **kw), operator=op)
        except Exception:
            return None
        v, s = sc.quick(r.points)
        return {"vertex": v, "surface": s}

    return lambda_oracle(ev, "vertex", memo, 1e-8, 1e4)["vertex"], lambda_oracle(
        ev, "surface", memo, 1e-8, 1e4
    )["surface"]


def auto(case, sc, **kw):
    r = smooth(geometry(case), SmoothingParams(**kw))
    return sc.quick(r.points)
