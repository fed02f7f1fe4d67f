"""``python -m benchmarks.quality.harm --half calibration|test|all [--tag after] [--before J]``.

Issue 40's families ("do no harm"): each phenomenon of the issue on two shapes, one per half
(:data:`FAMILIES`; thresholds are chosen on the calibration half only), at noise levels from 0.02
to 2 edges. Per case: geosmooth's default (no smoothing parameter) against fixed Taubin (10 and
50 iterations, :func:`benchmarks.quality.issue31.taubin`), scored as ratios to the input's error
(:class:`benchmarks.quality.targets.Issue31Scorer`) plus the issue's own numbers: boundary
vertices' error against the input's, closed volume against the truth's, whether a volume warning
names the wrong direction, how far apart exact duplicates end, sigma^ / sigma, and the residual
test's back-off (the points its warning names). ``--before`` puts a former run's numbers beside.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import re
import sys
import time
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.measure import machine_info
from benchmarks.quality import harmshapes as hs
from benchmarks.quality import surfaces
from benchmarks.quality.cases import Case
from benchmarks.quality.issue31 import TAUBIN_ITERATIONS, _commit, taubin
from benchmarks.quality.run import write_tables
from benchmarks.quality.shapes import Shape
from benchmarks.quality.targets import Issue31Scorer
from service.core import Geometry, SmoothingParams, smooth

__all__ = ["FAMILIES", "cases", "make", "run_case"]

RESULTS = Path(__file__).resolve().parent / "results"
C, T = "calibration", "test"
LEVELS = (0.02, 0.25, 1.0)
#: family -> (phenomenon, builder, noise model, half, levels)
FAMILIES: dict[str, tuple[str, Callable[[], Shape], str, str, tuple[float, ...]]] = {
    "plate-0.25": ("thin plate", lambda: hs.plate(0.25), "normal", C, LEVELS),
    "plate-0.3": ("thin plate", lambda: hs.plate(0.3), "normal", T, (0.017, 0.25, 1.0)),
    "cyl-4": ("CAD triangles", lambda: hs.cylinder(4), "normal", C, LEVELS),
    "cyl-10": ("CAD triangles", lambda: hs.cylinder(10), "normal", C, LEVELS),
    "cyl-20": ("CAD triangles", lambda: hs.cylinder(20), "normal", T, LEVELS),
    "cyl-6": ("CAD triangles", lambda: hs.cylinder(6, ntheta=150), "normal", T, LEVELS),
    "fold-3": ("thin fold", lambda: hs.fold(3.0), "normal", C, LEVELS),
    "fold-2.2": ("thin fold", lambda: hs.fold(2.2), "normal", T, LEVELS),
    "cup-2.5": ("thin wall", lambda: hs.cup(2.5), "normal", C, LEVELS),
    "cup-2": ("thin wall", lambda: hs.cup(2.0), "normal", T, LEVELS),
    "stairs-0.15": ("steps", lambda: hs.stairs(rise=0.15), "vert", C, LEVELS),
    "stairs-0.25": ("steps", lambda: hs.stairs(rise=0.25), "vert", T, LEVELS),
    "holes-4": ("boundaries", lambda: hs.holed_plate(4), "iso", C, LEVELS),
    "holes-9": ("boundaries", lambda: hs.holed_plate(9), "iso", T, LEVELS),
    "height-50": ("boundaries", lambda: surfaces.terrain(50), "iso", C, LEVELS),
    "height-73": ("boundaries", lambda: surfaces.terrain(73), "iso", T, LEVELS),
    "ellipsoid-b": ("coarse", lambda: hs.ellipsoid(1.0, 0.7, 16, 32), "normal", C,
                    (0.25, 1.0, 2.0)),
    "ellipsoid-a": ("coarse", lambda: hs.ellipsoid(1.0, 0.6, 12, 24), "normal", T,
                    (0.25, 1.0, 2.0)),
    "dup-b": ("duplicates", lambda: hs.duplicated_cloud(4000, 0.005, 7), "iso", C, LEVELS),
    "dup-a": ("duplicates", lambda: hs.duplicated_cloud(5000, 0.005, 3), "iso", T, LEVELS),
}
_SHAPES: dict[str, Shape] = {}


def cases(half: str) -> list[str]:
    """``"<family>/<level>"`` keys of one half (``"all"``: both)."""
    return [f"{f}/{lv:g}" for f, (_, _, _, h, lvs) in FAMILIES.items() for lv in lvs
            if half in ("all", h)]


def make(key: str) -> Case:
    """The noisy case ``"<family>/<level>"`` (seeded by the key)."""
    fam, level_s = key.split("/")
    _, build, noise, _, _ = FAMILIES[fam]
    if fam not in _SHAPES:
        _SHAPES[fam] = build()
    shape = _SHAPES[fam]
    level = float(level_s)
    sigma = level * shape.h
    rng = np.random.default_rng(zlib.crc32(key.encode()))
    G = rng.normal(size=shape.points.shape)
    if noise == "normal":
        E = sigma * G[:, :1] * shape.frame[:, :, 0]
    elif noise == "vert":
        E = sigma * G * np.array([0.0, 0.0, 1.0])
    else:
        E = sigma * G
    X = shape.points + E
    copies = shape.extra.get("copies")
    if isinstance(copies, np.ndarray):
        X[copies[:, 1]] = X[copies[:, 0]]
    return Case(key, shape, noise, level, X, sigma, np.zeros(shape.n, dtype=bool))


def _volume(X: np.ndarray, F: np.ndarray) -> float:
    return float(np.sum(X[F[:, 0]] * np.cross(X[F[:, 1]], X[F[:, 2]])) / 6.0)


def _extras(case: Case, X: np.ndarray, report: dict[str, Any]) -> dict[str, Any]:
    """Boundary, volume, duplicates and warning direction numbers of result ``X``."""
    sh, P = case.shape, case.points
    out: dict[str, Any] = {}
    if sh.faces is not None:
        b = hs.boundary_vertices(sh.faces, sh.n)
        if b.any():
            e_in = np.sqrt(np.mean(np.sum((P[b] - sh.points[b]) ** 2, axis=1)))
            e_out = np.sqrt(np.mean(np.sum((X[b] - sh.points[b]) ** 2, axis=1)))
            out["boundary"] = float(e_out / e_in) if e_in > 0 else None
        if sh.closed:
            v0, vin, vout = (_volume(Y, sh.faces) for Y in (sh.points, P, X))
            out["volume_pct"] = 100 * (vout - v0) / v0
            out["volume_input_pct"] = 100 * (vin - v0) / v0
            said = [w for w in report.get("warnings") or [] if "enclosed volume" in w]
            grew = vout > vin
            wrong = [w for w in said if ("shrank" in w and grew) or ("grew" in w and not grew)]
            out["wrong_way"] = len(wrong)
    copies = sh.extra.get("copies")
    if isinstance(copies, np.ndarray):
        gap = np.linalg.norm(X[copies[:, 0]] - X[copies[:, 1]], axis=1)
        out["dup_gap_h"] = float(gap.max() / sh.h)
    return out


def run_case(key: str) -> dict[str, Any]:
    """The default and fixed Taubin on one case, scored (JSON-ready)."""
    case = make(key)
    fam = key.split("/")[0]
    scorer = Issue31Scorer(case)
    out: dict[str, Any] = {"key": key, "family": fam, "phenomenon": FAMILIES[fam][0],
                           "half": FAMILIES[fam][3], "n": case.n, "noise": case.noise,
                           "level": case.level, "sigma": case.sigma,
                           "source": case.shape.source}
    geometry = Geometry(case.points, faces=case.shape.faces)
    t0 = time.process_time()
    try:
        res = smooth(geometry, SmoothingParams())
    except Exception as exc:  # a failure of the default is a result
        out.update(error=f"{type(exc).__name__}: {exc}")
        return out
    out["cpu_seconds"] = time.process_time() - t0
    rep = res.report()
    out["report"] = {k: rep.get(k) for k in ("sigma_estimate", "noise_found", "tau", "lambda",
                                             "warnings", "data_weights")}
    said = [w for w in rep.get("warnings") or [] if w.startswith("residual test:")]
    out["backoff_points"] = int(re.search(r"at (\d+) points", said[0])[1]) if said else 0
    out["sigma_ratio"] = (rep.get("sigma_estimate") or 0.0) / case.sigma
    out["auto"] = {**scorer.score(res.points), **_extras(case, res.points, rep)}
    tb = {}
    for it in TAUBIN_ITERATIONS:
        try:
            X = taubin(case, it)
            tb[f"x{it}"] = {**scorer.score(X), **_extras(case, X, {})}
        except RuntimeError as exc:
            tb[f"x{it}"] = {"error": str(exc)}
    out["taubin"] = tb
    best = min((t["surface"] for t in tb.values() if t.get("surface") is not None), default=None)
    out["vs_taubin"] = out["auto"]["surface"] / best if best else None
    return out


def _f(x: Any, fmt: str = ".2f") -> str:
    return "–" if x is None else format(x, fmt)


def render(doc: dict[str, Any]) -> str:
    """The markdown table of a run (with the ``before`` numbers when present)."""
    before = {c["key"]: c for c in doc.get("before", [])}
    lines = [f"# Issue 40 families ({doc['half']}), commit {doc.get('commit')}", "",
             f"CPU {doc['cpu_seconds']:.0f} s, load at end {doc['load_end'][0]:.1f}. "
             "Ratios to the input's error; `a → b`: before → after.", "",
             "| case | phenomenon | half | σ̂/σ | RMS error | distance | vs better Taubin | "
             "boundary | volume % (input) | dup gap h | backed-off points | warnings |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for c in doc["cases"]:
        b = before.get(c["key"], {})
        if "error" in c:
            lines.append(f"| {c['key']} | {c['phenomenon']} | {c['half']} | error: "
                         f"{c['error']} |")
            continue

        def pair(get: Callable[[dict[str, Any]], Any], fmt: str = ".2f",
                 b: dict[str, Any] = b, c: dict[str, Any] = c) -> str:
            now = _f(get(c), fmt)
            try:
                was = get(b) if b and "error" not in b else None
            except (KeyError, TypeError):
                was = None
            return now if was is None else f"{_f(was, fmt)} → {now}"

        a = c["auto"]
        warn = "; ".join(w[:50] for w in c["report"].get("warnings") or [])
        bo = c.get("backoff_points", 0)
        lines.append(
            f"| {c['key']} | {c['phenomenon']} | {c['half'][0]} "
            f"| {pair(lambda r: r['sigma_ratio'])} "
            f"| {pair(lambda r: r['auto']['vertex'])} | {pair(lambda r: r['auto']['surface'])} "
            f"| {pair(lambda r: r['vs_taubin'])} | {pair(lambda r: r['auto'].get('boundary'))} "
            f"| {pair(lambda r: r['auto'].get('volume_pct'), '+.1f')} "
            f"({_f(a.get('volume_input_pct'), '+.1f')}) "
            f"| {pair(lambda r: r['auto'].get('dup_gap_h'), '.3g')} "
            f"| {bo or '–'} | {warn} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Run one half (or both); returns the exit status."""
    ap = argparse.ArgumentParser(prog="python -m benchmarks.quality.harm", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--half", choices=("calibration", "test", "all"), default="all")
    ap.add_argument("--cases", nargs="+", metavar="KEY")
    ap.add_argument("--out", type=Path, default=RESULTS)
    ap.add_argument("--tag", default="run")
    ap.add_argument("--before", type=Path, help="a former run's .json to put beside")
    args = ap.parse_args(argv)
    keys = args.cases or cases(args.half)
    cpu0 = time.process_time()
    results = []
    for i, key in enumerate(keys, 1):
        t = time.process_time()
        results.append(run_case(key))
        print(f"[{i}/{len(keys)}] {key}: {time.process_time() - t:.1f} s CPU", file=sys.stderr,
              flush=True)
    doc: dict[str, Any] = {"machine": machine_info(), "half": args.half, "cases": results,
                           "cpu_seconds": time.process_time() - cpu0,
                           "load_end": list(os.getloadavg()), "commit": _commit()}
    if args.before:
        doc["before"] = json.loads(args.before.read_text())["cases"]
    stem = f"harm40-{args.tag}-{args.half}-{dt.datetime.now(dt.UTC):%Y-%m-%d}"
    print(write_tables(args.out, stem, doc, render))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
