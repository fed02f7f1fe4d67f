"""geosmooth on a benchmark case: its modes at their oracle lambda, and the automatic tau.

A *mode* is a set of :class:`~service.core.SmoothingParams` fields other than lam/tau/rms
(weights, Laplacian variant, displacement, order, neighbourhoods, ...). Its oracle is the best
lambda for each metric (:func:`benchmarks.quality.sweep.lambda_oracle`); the default mode is
also run with no smoothing parameter at all (automatic tau) and with that tau given explicitly,
to measure what the automatic choice costs.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from pydantic import ValidationError

from benchmarks.quality.cases import Case
from benchmarks.quality.scores import Scorer
from benchmarks.quality.sweep import lambda_oracle
from service.core import Geometry, SmoothingParams, smooth
from service.core.errors import GeosmoothError
from service.core.operator.build import SmoothingOperator, build_operator

__all__ = ["MODES", "geometry_of", "modes_for", "operator_for", "run_auto", "run_mode"]

#: name -> (kinds it applies to, SmoothingParams fields)
MODES: dict[str, tuple[tuple[str, ...], dict[str, Any]]] = {
    "report": (("mesh", "curve", "cloud"), {"preset": "report"}),
    "default": (("mesh", "curve", "cloud"), {}),
    "free, order 2": (("mesh", "curve", "cloud"), {"displacement": "free", "order": 2}),
    "free, order 3": (("mesh", "curve", "cloud"), {"displacement": "free", "order": 3}),
    "normal, order 2": (("mesh", "cloud"), {"displacement": "normal", "order": 2}),
    "free, L(f)": (("mesh",), {"displacement": "free", "laplacian": "feature"}),
    "windowed-sinc": (("mesh", "curve"), {"displacement": "free", "method": "windowed-sinc"}),
}


def geometry_of(case: Case) -> Geometry:
    """The noisy input as a :class:`Geometry`."""
    return Geometry(case.points, faces=case.shape.faces, edges=case.shape.edges)


def _params(**kw: Any) -> SmoothingParams | None:
    try:
        return SmoothingParams(**kw)
    except (ValidationError, TypeError):
        return None  # a mode this version of geosmooth does not have


def modes_for(case: Case, names: list[str] | None = None) -> dict[str, dict[str, Any]]:
    """The modes that apply to ``case`` and that this geosmooth accepts."""
    out = {}
    for name, (kinds, kw) in MODES.items():
        if names is not None and name not in names:
            continue
        if case.shape.kind in kinds and _params(lam=1.0, **kw) is not None:
            out[name] = kw
    return out


def _run(
    case: Case, scorer: Scorer, params: SmoothingParams, operator: Any = None
) -> dict[str, Any] | None:
    try:
        t0 = time.process_time()  # CPU seconds: steadier than wall time on a shared machine
        res = smooth(geometry_of(case), params, operator=operator)
        seconds = time.process_time() - t0
    except GeosmoothError:
        return None
    rep = res.report()
    out = scorer.full(res.points)
    out.update(lam=res.lam, tau=res.phi, seconds=seconds,
               factorizations=res.factorizations, report=_small_report(rep))
    return out


def _small_report(rep: dict[str, Any]) -> dict[str, Any]:
    keep = ("sigma_estimate", "tau_rule", "tau", "phi", "lambda", "iterations", "warnings",
            "flipped_faces", "volume_change", "area_change", "weights", "max_deviation_iterations")
    return {k: rep[k] for k in keep if k in rep}


def operator_for(case: Case, kw: dict[str, Any]) -> SmoothingOperator | None:
    """The operator of mode ``kw`` on ``case``, built once for its lambda scan (``None`` when
    this geosmooth lacks the mode or cannot build it: each run then reports its own error)."""
    p0 = _params(lam=1.0, **kw)
    try:
        return build_operator(geometry_of(case), p0) if p0 is not None else None
    except GeosmoothError:
        return None


def run_mode(case: Case, scorer: Scorer, kw: dict[str, Any]) -> dict[str, Any]:
    """Oracle lambda of one mode for each metric: ``{"vertex": row, "surface": row}``."""
    memo: dict[float, dict[str, Any] | None] = {}
    op = operator_for(case, kw)

    def evaluate(lam: float) -> dict[str, Any] | None:
        p = _params(lam=lam, **kw)
        return None if p is None else _run(case, scorer, p, op)

    return {m: lambda_oracle(evaluate, m, memo) for m in ("vertex", "surface")}


def run_auto(case: Case, scorer: Scorer, kw: dict[str, Any] | None = None,
             repeats: int = 3) -> dict[str, Any] | None:
    """The mode ``kw`` (default: the defaults) with no smoothing parameter (automatic tau).

    Also runs the same mode with the tau it chose given explicitly (median of ``repeats``
    timings each) to measure the cost of the automatic choice.
    """
    kw = kw or {}
    p = _params(**kw)
    if p is None:
        return None
    auto = _run(case, scorer, p)
    if auto is None:
        return None
    t_auto = [auto["seconds"]]
    if repeats == 0:
        return auto
    given = _params(**{**kw, "tau": auto["tau"]})
    assert given is not None
    t_given = []
    for _ in range(repeats):
        r = _run(case, scorer, given)
        if r is not None:
            t_given.append(r["seconds"])
        r = _run(case, scorer, p)
        if r is not None:
            t_auto.append(r["seconds"])
    auto["cost_ratio"] = float(np.median(t_auto) / np.median(t_given)) if t_given else None
    return auto
