"""Calibration of the automatic tau: ``python -m benchmarks.quality.calibrate [--quick]``.

For every calibration case and candidate mode, geosmooth is run at ``tau = k x r sigma^2 n``
(``sigma`` the *estimated* noise, ``r`` normal directions, ``k`` on a log grid); the errors
against the ground truth give, per case, the error of any rule ``k(case)`` relative to the best
``k`` of the grid. The constants of :func:`service.core.search.autotau.discrepancy_tau` are those
minimizing the mean log ratio over cases and both metrics (vertex error, distance to the true
surface): ``c`` for normal displacement, ``(c, alpha)`` with ``k = c (1 + alpha rho)`` for free
displacement. Writes ``results/calibration-<date>.json`` and prints the fit.
"""

from __future__ import annotations

import argparse
import datetime as dt
import itertools
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.quality.cases import make_case
from benchmarks.quality.ours import geometry_of
from benchmarks.quality.scores import Scorer
from service.core import SmoothingParams, smooth
from service.core.errors import GeosmoothError
from service.core.noise.estimate import codimension, estimate_noise
from service.core.operator.build import build_operator
from service.core.system.displacement import tangential_ratio

RESULTS = Path(__file__).resolve().parent / "results"
GRID = np.geomspace(0.25, 8.0, 31)
CANDIDATES: dict[str, dict[str, Any]] = {
    "free": {"displacement": "free", "weights": "uniform", "order": 2},
    "normal": {"displacement": "normal", "weights": "uniform", "order": 2},
}
SHAPES = ["sphere-2.5K", "torus-5.8K", "box", "fandisk", "spot", "circle-2d", "trefoil-3d",
          "cloud-sphere"]
CASES = [f"{s}/{n}-{lv:g}" for s in SHAPES for n in ("normal", "iso", "aniso")
         for lv in (0.1, 0.25, 0.5)]
QUICK = [f"{s}/{n}-0.25" for s in ("sphere-2.5K", "fandisk", "circle-2d", "cloud-sphere")
         for n in ("normal", "iso", "aniso")]


def measure(key: str, modes: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Errors on the k grid for every mode, plus sigma-hat and rho.

    The solves are made at given lambdas around the lambda of ``k = 1`` (one factorization
    each, no search); the errors at the grid's ``k = phi / (r sigma^2 n)`` are interpolated in
    ``log phi``.
    """
    case = make_case(key)
    scorer = Scorer(case)
    g = geometry_of(case)
    est = estimate_noise(g)
    assert est is not None
    r = codimension(g)
    out: dict[str, Any] = {"key": key, "kind": case.shape.kind, "sigma": case.sigma,
                           "sigma_hat": est.sigma, "modes": {}}
    base = r * est.sigma**2 * g.n
    for name, kw in modes.items():
        params = SmoothingParams(tau=base, **kw)
        op = build_operator(g, params)
        rho = tangential_ratio(g.points, op.neighborhoods.adjacency, r) if r else 0.0
        lam0 = smooth(g, params, operator=op).lam
        samples = []
        for e in np.arange(-2.5, 2.51, 0.25):
            try:
                res = smooth(g, params.model_copy(update={"tau": None, "lam": lam0 * 10**e}),
                             operator=op)
            except GeosmoothError:
                continue
            samples.append((res.phi / base, *scorer.quick(res.points)))
        samples.sort()
        ks = np.log([x[0] for x in samples])
        rows: list[Any] = []
        for k in GRID:
            if not ks[0] <= math.log(k) <= ks[-1]:
                rows.append(None)
                continue
            rows.append([float(np.interp(math.log(k), ks, [x[i] for x in samples]))
                         for i in (1, 2)])
        best = [min(x[i] for x in samples) for i in (1, 2)]
        out["modes"][name] = {"rho": rho, "errors": rows, "best": best}
    return out


def _ratio(errors: list[Any], k: float, metric: int, best: list[float]) -> float:
    """Error at ``k`` (log-interpolated on the grid) over the best of the lambda scan."""
    pts = [(math.log(g), e[metric]) for g, e in zip(GRID, errors, strict=True) if e is not None]
    if not pts:
        return math.nan
    x, y = np.array([p[0] for p in pts]), np.array([p[1] for p in pts])
    at = float(np.interp(math.log(k), x, y, left=y[0] * 10, right=y[-1] * 10))
    return at / best[metric]


def fit(data: list[dict[str, Any]], mode: str) -> dict[str, Any]:
    """Best constants for ``mode`` and the ratios they give."""
    cs = np.geomspace(0.4, 2.5, 41)
    alphas = np.linspace(0.0, 1.5, 16) if mode == "free" else np.array([0.0])
    best: tuple[float, float, float] | None = None
    for c, a in itertools.product(cs, alphas):
        logs = [math.log(_ratio(d["modes"][mode]["errors"], c * (1 + a * d["modes"][mode]["rho"]),
                                m, d["modes"][mode]["best"])) for d in data for m in (0, 1)]
        score = float(np.nanmean(logs))
        if best is None or score < best[0]:
            best = (score, float(c), float(a))
    assert best is not None
    _, c, a = best
    ratios = [[_ratio(d["modes"][mode]["errors"], c * (1 + a * d["modes"][mode]["rho"]), m,
                      d["modes"][mode]["best"]) for m in (0, 1)] for d in data]
    arr = np.array(ratios)
    return {"c": c, "alpha": a, "median_ratio": np.nanmedian(arr, axis=0).tolist(),
            "within_1.15": np.nanmean(arr <= 1.15, axis=0).tolist(),
            "max_ratio": np.nanmax(arr, axis=0).tolist()}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.quality.calibrate")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--cases", nargs="+")
    ap.add_argument("--out", type=Path, default=RESULTS)
    args = ap.parse_args(argv)
    keys = args.cases or (QUICK if args.quick else CASES)
    t0 = time.perf_counter()
    data = []
    partial = args.out / "calibration-partial.json"
    for i, key in enumerate(keys, 1):
        data.append(measure(key, CANDIDATES))
        print(f"[{i}/{len(keys)}] {key}", file=sys.stderr, flush=True)
        args.out.mkdir(parents=True, exist_ok=True)
        partial.write_text(json.dumps(data))
    fits = {}
    for mode in CANDIDATES:
        for kind in ("mesh", "curve", "cloud", "all"):
            sub = [d for d in data if kind in ("all", d["kind"])]
            if sub:
                fits[f"{mode}/{kind}"] = fit(sub, mode)
    doc = {"grid": GRID.tolist(), "candidates": CANDIDATES, "cases": data, "fits": fits,
           "seconds": time.perf_counter() - t0}
    day = dt.datetime.now(dt.UTC).strftime("%Y-%m-%d")
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / (f"calibration-{day}" + ("-quick" if args.quick else "") + ".json")
    path.write_text(json.dumps(doc, indent=1))
    for name, f in fits.items():
        print(f"{name:14s} c={f['c']:.3f} alpha={f['alpha']:.2f}  median ratio (vertex, surface)"
              f" {f['median_ratio'][0]:.3f} {f['median_ratio'][1]:.3f}  within 1.15x"
              f" {f['within_1.15'][0]:.2f} {f['within_1.15'][1]:.2f}  max"
              f" {f['max_ratio'][0]:.2f} {f['max_ratio'][1]:.2f}")
    print(f"wrote {path} ({doc['seconds']:.0f} s)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
