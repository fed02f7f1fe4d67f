"""``python -m benchmarks.quality.halves --half test|calibration|all [--cache DIR] [--out DIR]``.

Issue 21's tables on one half of the fixed split (:mod:`benchmarks.quality.families`): per
case the automatic tau (geosmooth with no smoothing parameter), geosmooth's own oracle (the best
of a few modes, each at its oracle lambda), every peer's swept best and its defaults, sigma^ /
sigma and flipped faces; then the issue's target rows and the wins and losses per noise model
and per shape. Writes ``<out>/halves-<half>-<date>.md`` and ``.json``.

Peer sweeps and the defaults do not depend on geosmooth: they are cached per case and peer
version in ``--cache`` (default ``$GEOSMOOTH_QUALITY_CACHE`` or ``results/cache``), so a run on
another geosmooth tree only redoes geosmooth. ``--peers-only`` fills the cache. The oracle is
kept cheap (:func:`cheap_oracle`): two modes per kind (:data:`ORACLE_MODES`), a decade scan
of lambda over +-2 decades around the automatic lambda (moved while the minimum is on its edge),
then parabolic steps (``--refine``, default 2) per metric.
"""

from __future__ import annotations

import argparse
import datetime as dt
import math
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from benchmarks.measure import machine_info
from benchmarks.quality.cases import make_case
from benchmarks.quality.defaults import DEFAULT_PEERS, SUFFIX
from benchmarks.quality.families import KIND, half_cases, half_of
from benchmarks.quality.halftable import render
from benchmarks.quality.ours import _params, _run, modes_for, operator_for
from benchmarks.quality.peers import QUALITY_PEERS, peer_versions
from benchmarks.quality.run import write_tables
from benchmarks.quality.scores import Scorer
from benchmarks.quality.sweep import best_of, sweep_peer

__all__ = ["main", "run_half_case"]

RESULTS = Path(__file__).resolve().parent / "results"
METRICS = ("vertex", "surface")
#: geosmooth's modes whose oracle is taken, per kind of input (the best of them is "geosmooth's
#: best mode"); on curves the default displacement is already free.
ORACLE_MODES: dict[str, list[str]] = {
    "mesh": ["default", "free, order 2"], "grid": ["default", "free, order 2"],
    "cloud": ["default", "free, order 2"], "curve": ["default", "windowed-sinc"],
}
DECADES = 2
Log = Callable[[str], None]


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def default_cache() -> Path:
    """``$GEOSMOOTH_QUALITY_CACHE`` or ``results/cache`` beside this file."""
    env = os.environ.get("GEOSMOOTH_QUALITY_CACHE")
    return Path(env) if env else RESULTS / "cache"


def _peers(case: Any, scorer: Scorer, cache: Path, log: Log) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for peer, twin in zip(QUALITY_PEERS, DEFAULT_PEERS, strict=True):
        if case.shape.kind not in peer.kinds:
            continue
        swept = sweep_peer(case, peer, scorer, False, cache, log)
        dflt = sweep_peer(case, twin, scorer, False, cache, log)
        row = dflt["rows"][0] if dflt["rows"] else None
        out[peer.name] = {
            "settings": len(swept["rows"]),
            "error": swept["error"],
            "swept": {m: best_of(swept["rows"], m) for m in METRICS},
            "defaults": row,
            "defaults_error": dflt["error"],
        }
    return out


def cheap_oracle(f: Callable[[float], float], center: float, decades: int = DECADES,
                 refine: int = 2, moves: int = 4) -> float:
    """The log10 lambda minimising ``f`` (of log10 lambda): decades ``center +- decades``
    (moved by a decade while the minimum is on the scan's edge, at most ``moves`` times), then
    ``refine`` steps of parabolic interpolation through the best point and its neighbours.
    ``f`` should be memoized: the metrics of one mode share its evaluations.
    """
    xs = [center + k for k in range(-decades, decades + 1)]
    vals = {x: f(x) for x in xs}
    for _ in range(moves):
        best = min(vals, key=lambda x: vals[x])
        if not math.isfinite(vals[best]):
            return best
        if best == min(vals):
            vals[best - 1] = f(best - 1)
        elif best == max(vals):
            vals[best + 1] = f(best + 1)
        else:
            break
    for _ in range(refine):
        xs = sorted(vals)
        i = xs.index(min(vals, key=lambda x: vals[x]))
        if i == 0 or i == len(xs) - 1:
            break
        a, b, c = xs[i - 1], xs[i], xs[i + 1]
        fa, fb, fc = vals[a], vals[b], vals[c]
        den = (b - a) * (fb - fc) - (b - c) * (fb - fa)
        if not all(map(math.isfinite, (fa, fb, fc))) or den == 0:
            break
        x = b - 0.5 * ((b - a) ** 2 * (fb - fc) - (b - c) ** 2 * (fb - fa)) / den
        x = min(max(x, a + 0.05 * (b - a)), c - 0.05 * (c - b))  # strictly inside the bracket
        if any(abs(x - y) < 1e-3 for y in vals):
            break
        vals[x] = f(x)
    return min(vals, key=lambda x: vals[x])


def _oracle(case: Any, scorer: Scorer, kw: dict[str, Any], lam0: float | None,
            refine: int) -> dict[str, Any]:
    memo: dict[float, dict[str, Any] | None] = {}
    op = operator_for(case, kw)

    def run(log_lam: float) -> dict[str, Any] | None:
        key = round(log_lam, 9)
        if key not in memo:
            p = _params(lam=float(10.0**log_lam), **kw)
            memo[key] = None if p is None else _run(case, scorer, p, op)
        return memo[key]

    out: dict[str, Any] = {}
    for m in METRICS:
        def f(x: float, m: str = m) -> float:
            r = run(x)
            return math.inf if r is None else float(r[m])

        best = cheap_oracle(f, round(math.log10(lam0)) if lam0 else -2.0, refine=refine)
        out[m] = run(best)
    out["evaluations"] = len(memo)
    return out


def _ours(case: Any, scorer: Scorer, modes: list[str], refine: int) -> dict[str, Any]:
    p = _params()
    auto = _run(case, scorer, p) if p is not None else None
    lam0 = auto["lam"] if auto and auto.get("lam") else None
    oracle = {name: _oracle(case, scorer, kw, lam0, refine)
              for name, kw in modes_for(case, modes).items()}
    return {"auto": auto, "modes": oracle}


def run_half_case(key: str, cache: Path, *, ours: bool = True, modes: list[str] | None = None,
                  refine: int = 2, log: Log = _log) -> dict[str, Any]:
    """All measurements of one case (JSON-ready)."""
    t0 = time.perf_counter()
    case = make_case(key)
    scorer = Scorer(case)
    shape_key = key.split("/")[0]
    out: dict[str, Any] = {
        "key": key, "half": half_of(key), "shape": shape_key, "noise": case.noise,
        "kind": KIND[shape_key], "label": case.label, "n": case.n, "level": case.level,
        "sigma": case.sigma, "outliers": int(case.outliers.sum()), "source": case.shape.source,
        "input": scorer.full(case.points),
    }
    out["peers"] = _peers(case, scorer, cache, log)
    t1 = time.perf_counter()
    if ours:
        try:
            out.update(_ours(case, scorer, modes or ORACLE_MODES[out["kind"]], refine))
        except Exception as exc:  # a crash of geosmooth on a case is a result, not the end
            out.update(auto=None, modes={}, error=f"{type(exc).__name__}: {exc}")
            log(f"    geosmooth failed: {out['error']}")
    out["seconds"] = time.perf_counter() - t0
    out["seconds_geosmooth"] = time.perf_counter() - t1
    return out


def main(argv: list[str] | None = None) -> int:
    """Run one half; returns the exit status."""
    ap = argparse.ArgumentParser(prog="python -m benchmarks.quality.halves", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--half", choices=("calibration", "test", "all"), default="test")
    ap.add_argument("--cases", nargs="+", metavar="KEY", help="a subset of the half's cases")
    ap.add_argument("--cache", type=Path, default=None, help="peer cache directory")
    ap.add_argument("--out", type=Path, default=RESULTS, help="results directory")
    ap.add_argument("--peers-only", action="store_true", help="fill the peer cache only")
    ap.add_argument("--modes", nargs="+", help="geosmooth oracle modes (default: per kind, "
                    "ORACLE_MODES)")
    ap.add_argument("--refine", type=int, default=2, help="parabolic steps per metric")
    ap.add_argument("--tag", default="", help="suffix of the output files (e.g. 'before')")
    ap.add_argument("--reverse", action="store_true",
                    help="run the cases last to first (the table keeps their order): a second "
                    "process filling the same cache from the other end")
    args = ap.parse_args(argv)
    cache = args.cache or default_cache()
    keys = args.cases or half_cases(args.half)
    info = machine_info()
    t0 = time.perf_counter()
    results = []
    for i, key in enumerate(keys[::-1] if args.reverse else keys, 1):
        r = run_half_case(key, cache, ours=not args.peers_only, modes=args.modes,
                          refine=args.refine)
        results.append(r)
        _log(f"[{i}/{len(keys)}] {key}: {r['seconds']:.1f} s "
             f"(geosmooth {r['seconds_geosmooth']:.1f} s)")
    if args.peers_only:
        return 0
    results.sort(key=lambda r: keys.index(r["key"]))
    doc = {"machine": info, "peers": peer_versions(), "half": args.half, "cases": results,
           "modes": args.modes or ORACLE_MODES, "refine": args.refine, "decades": DECADES,
           "seconds": time.perf_counter() - t0,
           "load_end": list(os.getloadavg()), "defaults_suffix": SUFFIX}
    day = dt.datetime.now(dt.UTC).strftime("%Y-%m-%d")
    stem = f"halves-{args.half}-{day}" + (f"-{args.tag}" if args.tag else "")
    print(write_tables(args.out, stem, doc, render))
    _log(f"wrote {args.out / stem}.md and .json ({doc['seconds']:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
