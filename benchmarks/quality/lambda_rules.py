"""``python -m benchmarks.quality.lambda_rules [--half calibration|test] [--cases KEY ...]``.

Issue 37: the candidate rules for the automatic lambda compared on the default's own system
(order 2, normal displacement, data weights, the tangential step), each at its lambda, against
the oracle lambda of the same system (the best of a log grid of exact CHOLMOD solves, the
finish stage included), errors against the ground truth as fractions of the input's.

Candidates (service/core/README.md, "Issues 37 + 38"): A discrepancy tau0; B today's default
(knee); C GCV; D UPRE with the local sigma^; E UPRE with Wahba's sigma^ at GCV's lambda;
F UPRE with sigma^ = max(local, Wahba) when Wahba's is not far below the local one, else the
local one. The risk curves come from one Lanczos run with probe columns
(:mod:`service.core.search.risk`), run to convergence here (the production run stops earlier).
Writes ``results/lambda-rules-<half>-<date>.json`` and prints a table.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.quality.cases import make_case
from benchmarks.quality.families import SPLIT, half_cases
from benchmarks.quality.ours import geometry_of
from benchmarks.quality.scores import Scorer
from service.core.linalg.cache import analysis_of
from service.core.linalg.lanczos_run import LanczosRun, TikhonovModel
from service.core.params import SmoothingParams
from service.core.pipeline import finish, plan_and_prepare, target
from service.core.search.risk import RiskCurves, invariant_radius, probe_block
from service.core.search.roots import LambdaSearch
from service.core.search.target import Solution
from service.core.system.deviation import Deviation

RESULTS = Path(__file__).resolve().parent / "results"
PROBES = 8


def _rows(problem: Any) -> np.ndarray:
    free = np.flatnonzero(~problem.fixed)
    rep = max(problem.system.size // max(free.size, 1), 1)
    return np.repeat(free, rep)


def curves(problem: Any, steps: int, probes: int = PROBES) -> tuple[RiskCurves, Deviation, int]:
    """Risk curves of ``problem``'s system from a Lanczos run of ``steps`` steps."""
    system = problem.system
    order = problem.params.order
    dev = Deviation(system, solver="cholmod", order=order, symbolic=analysis_of)
    d = np.sqrt(system.d2)
    inv_d = (1.0 / d)[:, None]
    c = inv_d * system.r
    rows = _rows(problem)
    ts = np.ones(rows.size)
    if problem.weights is not None:
        ts = problem.weights.tau_scale[rows]
    S = d * ts
    rho = invariant_radius(problem.geometry.points[rows])
    Z = probe_block(rho, probes) * S[:, None]
    apply = lambda V: inv_d * dev.solver.matvec(inv_d * V)  # noqa: E731
    run = LanczosRun(apply, np.hstack([c, Z]), keep_bytes=0)
    for _ in range(min(steps, system.size)):
        run.step()
        if run.done:
            break
    model = run.model(order)
    cols = c.shape[1]
    rc = RiskCurves(TikhonovModel(model.columns[:cols], order),
                    TikhonovModel(model.columns[cols:], order), probes, cols,
                    float(np.sum(S**2)))  # fmt: skip
    return rc, dev, run.steps


def _score(problem: Any, plan: Any, aim: Any, dev: Deviation, lam: float,
           scorer: Scorer) -> tuple[float, float]:  # fmt: skip
    U = dev.solution(lam)
    sol = Solution(aim, LambdaSearch(lam, dev(lam), True, []), U, dev)
    X = finish(problem, plan, sol).X
    return scorer.quick(X)


def run_case(key: str, steps: int) -> dict[str, Any]:
    from service.core import smooth

    case = make_case(key)
    scorer = Scorer(case)
    g = geometry_of(case)
    t0 = time.process_time()
    default = smooth(g, SmoothingParams())
    t_default = time.process_time() - t0
    plan, problem = plan_and_prepare(g, SmoothingParams())
    aim = target(problem, plan)
    out: dict[str, Any] = {"key": key, "n": case.n, "sigma_true": case.sigma}
    if not aim.tau or problem.system.empty:
        out["skipped"] = aim.how
        return out
    frame = problem.frame
    sig_l = aim.sigma / frame.scale
    rc, dev, done = curves(problem, steps)
    cols = rc.columns
    lo = dev.floor
    tau0 = frame.tau_in(aim.tau)
    hi = max(problem.system.lambda_ceiling(tau0 * 1e-3), lo * 10)
    lams: dict[str, float] = {}
    lams["A tau0"] = float(_root(rc, tau0, lo, hi))
    lams["B default"] = frame.lam_in(default.lam) if default.lam else math.nan
    lams["C gcv"] = rc.gcv_min(lo, hi)
    sig_w2 = rc.wahba_sigma2(lams["C gcv"])
    lams["D upre local"] = rc.upre_min(sig_l**2, lo, hi)
    lams["E upre wahba"] = rc.upre_min(sig_w2, lo, hi)
    hyb = max(sig_l**2, sig_w2) if sig_w2 >= 0.5 * sig_l**2 else sig_l**2
    lams["F hybrid"] = rc.upre_min(hyb, lo, hi)
    true_s = case.sigma / frame.scale / frame.weight_scale
    lams["G upre true"] = rc.upre_min(true_s**2, lo, hi)
    scores = {name: _score(problem, plan, aim, dev, lam, scorer) for name, lam in lams.items()
              if math.isfinite(lam)}  # fmt: skip
    finite = [v for v in lams.values() if math.isfinite(v)]
    grid = np.geomspace(max(min(finite) / 30, lo * 1.01), max(finite) * 30, 25)
    oracle = [(lam, *_score(problem, plan, aim, dev, float(lam), scorer)) for lam in grid]
    best_v = min(oracle, key=lambda r: r[1])
    best_s = min(oracle, key=lambda r: r[2])
    out.update(
        sigma_local=aim.sigma, sigma_wahba=math.sqrt(sig_w2) * frame.scale,
        steps=done, seconds_default=t_default, lambdas=lams, scores=scores,
        oracle_vertex=best_v, oracle_surface=best_s,
        default_scores=scorer.quick(default.points), columns=cols,
    )
    return out


def _root(rc: RiskCurves, tau: float, lo: float, hi: float) -> float:
    a, b = math.log(lo), math.log(hi)
    if float(rc.phi(np.asarray(lo))) <= tau:
        return lo
    for _ in range(200):
        mid = 0.5 * (a + b)
        if float(rc.phi(np.asarray(math.exp(mid)))) > tau:
            a = mid
        else:
            b = mid
    return math.exp(0.5 * (a + b))


def matrix(half: str, levels: list[float]) -> list[str]:
    """The noise matrix of one half: the shapes whose isotropic family is in that half,
    at each level (edge lengths)."""
    shapes = sorted(s for (s, nz), h in SPLIT.items() if nz == "iso" and h == half)
    return [f"{s}/iso-{lv:g}" for s in shapes for lv in levels]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--half", default="calibration")
    ap.add_argument("--cases", nargs="*")
    ap.add_argument("--steps", type=int, default=1500)
    ap.add_argument("--out")
    ap.add_argument("--levels", nargs="*", type=float, help="iso noise levels of the matrix")
    a = ap.parse_args(argv)
    keys = a.cases or (matrix(a.half, a.levels) if a.levels else half_cases(a.half))
    rows = []
    for key in keys:
        try:
            r = run_case(key, a.steps)
        except Exception as exc:
            r = {"key": key, "error": repr(exc)}
        rows.append(r)
        print(_line(r), flush=True)
    path = Path(a.out) if a.out else RESULTS / f"lambda-rules-{a.half}-{dt.date.today()}.json"
    path.write_text(json.dumps(rows, indent=1, default=float))
    path.with_suffix(".md").write_text(f"# lambda rules, {a.half}\n\n" + table(rows))
    print(table(rows))
    return 0


def _line(r: dict[str, Any]) -> str:
    if "scores" not in r:
        return f"{r['key']}: {r.get('skipped') or r.get('error')}"
    ov, os_ = r["oracle_vertex"][1], r["oracle_surface"][2]
    parts = [f"{r['key']:32s} sL/sW/s {r['sigma_local'] / r['sigma_true']:.2f}/"
             f"{r['sigma_wahba'] / r['sigma_true']:.2f}"]
    for name, (v, s) in r["scores"].items():
        parts.append(f"{name.split()[0]} {v / ov:.3f}/{s / os_:.3f}")
    return "  ".join(parts)


if __name__ == "__main__":
    sys.exit(main())


def table(rows: list[dict[str, Any]]) -> str:
    """Markdown: per candidate, the error over the oracle lambda's (vertex / surface), median
    and worst over the cases, and the count within 5 % of the oracle."""
    done = [r for r in rows if "scores" in r]
    names = list(done[0]["scores"]) if done else []
    out = ["| candidate | vertex median | vertex worst | surface median | surface worst | "
           "within 5 % (v) |", "|---|---|---|---|---|---|"]
    for name in names:
        v = np.array([r["scores"][name][0] / r["oracle_vertex"][1] for r in done
                      if name in r["scores"]])
        s = np.array([r["scores"][name][1] / r["oracle_surface"][2] for r in done
                      if name in r["scores"]])
        out.append(f"| {name} | {np.median(v):.3f} | {v.max():.3f} | {np.median(s):.3f} | "
                   f"{s.max():.3f} | {int(np.sum(v <= 1.05))}/{v.size} |")
    skipped = [r["key"] for r in rows if "scores" not in r]
    if skipped:
        out.append(f"\nNot smoothed by the default (no noise found, or an error): "
                   f"{', '.join(skipped)}.")
    return "\n".join(out) + "\n"
