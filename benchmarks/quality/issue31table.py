"""Markdown of issue 31's table (:mod:`benchmarks.quality.issue31`): per half, the targets'
counts, then one table per phenomenon and the noise-free inputs."""

from __future__ import annotations

from typing import Any

from benchmarks.quality.targets import CLEAN_MOVE, SIGMA_TOL, STRAY_SIGMAS, TAUBIN_FACTOR

__all__ = ["TITLES", "render", "summary"]

TITLES = {
    "cad": "Uniform Gaussian noise on CAD shapes (corners, creases)",
    "quant": "Quantized coordinates (grid step = level x h)",
    "high": "High noise (1 and 1.5 h) on regular meshes",
    "gps": "GPS-like tracks: 90/45/135 degree corners, uneven spacing, AR(1) noise",
    "stray": "Clouds with stray points 10 - 50 h off the surface (bulk scores; strays apart)",
}
HALVES = ("calibration", "test")


def _f(x: Any, fmt: str = ".3g") -> str:
    if x is None:
        return "-"
    if isinstance(x, float) and x == float("inf"):
        return "inf"
    return format(x, fmt)


def _count(cases: list[dict[str, Any]], name: str) -> str:
    vals = [c["checks"][name] for c in cases if c.get("checks") and c["checks"][name] is not None]
    if not vals:
        return "-"
    return f"{sum(vals)} / {len(vals)}"


def summary(cases: list[dict[str, Any]]) -> dict[str, str]:
    """The targets' counts (met / applicable) on a list of case results."""
    false = [w for c in cases if c.get("checks") for w in c["checks"]["false_warnings"]]
    kinds: dict[str, int] = {}
    for w in false:
        kinds[w] = kinds.get(w, 0) + 1
    return {
        "never worse than the input (vertex and surface)": _count(cases, "not_worse"),
        f"clean input moved <= {CLEAN_MOVE:g} h RMS": _count(cases, "clean_still"),
        "noisy input (sigma >= 0.1 h) smoothed": _count(cases, "smoothed"),
        f"surface <= {TAUBIN_FACTOR:g} x best of Taubin x10 / x50": _count(cases, "vs_taubin"),
        f"sigma^ within +-{100 * SIGMA_TOL:.0f} %": _count(cases, "sigma_ok"),
        f"no stray moved > {STRAY_SIGMAS:g} sigma^": _count(cases, "strays_ok"),
        "false warnings": (", ".join(f"{k}: {v}" for k, v in sorted(kinds.items()))
                           if kinds else "none"),
        "failed runs": str(sum(1 for c in cases if c.get("error"))),
    }


def _flags(c: dict[str, Any]) -> str:
    fl = c["flags"]
    false = c["checks"]["false_warnings"]
    out = []
    if fl["no_noise"]:
        out.append("no-noise")
    if fl["noise_weights"]:
        out.append("NW" + ("!" if "noise weights on uniform noise" in false else ""))
    if fl["outliers"]:
        out.append(f"out {fl['outliers']}" + ("!" if "outliers on outlier-free noise" in false
                                                else ""))
    if fl["flattened"]:
        out.append("flat" + ("!" if "flattened but under-smoothed" in false else ""))
    if fl["moved_far"]:
        out.append("moved")
    return " ".join(out)


def _row(c: dict[str, Any]) -> str:
    if c.get("error") or not c.get("auto"):
        return f"| {c['key']} | {c['n']} | {_f(c['sigma_h'])} | failed: {c.get('error')} |" + \
            " |" * 8
    a, ck, tb = c["auto"], c["checks"], c["taubin"]
    t10, t50 = (tb.get(k) or {} for k in ("x10", "x50"))
    stray = (f"{_f(ck['stray_sigmas'], '.3g')} ({_f(a['stray_max_h'], '.3g')} h)"
             if ck["stray_sigmas"] is not None else "-")
    return (f"| {c['key']} | {c['n']} | {_f(c['sigma_h'])} | {_f(a['vertex'])} | "
            f"{_f(a['surface'])} | {_f(t10.get('surface'))} | {_f(t50.get('surface'))} | "
            f"{_f(ck['taubin_ratio'])} | {_f(ck['sigma_ratio'])} | "
            f"{_f(a['measure_pct'], '+.1f')} | {stray} | {_flags(c)} |")


HEADER = ("| case | n | sigma/h | auto v | auto s | Taubin x10 s | x50 s | s / best Taubin | "
          "sigma^/sigma | area or length vs clean % | strays' max move / sigma^ (h) | flags |\n"
          "|---|---|---|---|---|---|---|---|---|---|---|---|")


def _clean_rows(cases: list[dict[str, Any]]) -> list[str]:
    out = ["| input | n | moved RMS / h | max move / h | sigma^ / h | warnings |",
           "|---|---|---|---|---|---|"]
    for c in cases:
        if not c.get("auto"):
            out.append(f"| {c['key']} | {c['n']} | failed: {c.get('error')} | | | |")
            continue
        rep = c["report"]
        out.append(f"| {c['key']} | {c['n']} | {_f(c['auto']['moved_h'])} | "
                   f"{_f((rep.get('max_displacement') or 0) / c['h'])} | "
                   f"{_f((c['sigma_hat'] or 0) / c['h'])} | "
                   f"{'; '.join(c['flags']['warnings']) or '-'} |")
    return out


def _draws(group: list[dict[str, Any]]) -> list[str]:
    """One line per case drawn with several seeds: how often each miss occurred."""
    bases: dict[str, list[dict[str, Any]]] = {}
    for c in group:
        bases.setdefault(c["key"].split("#")[0], []).append(c)
    out = []
    for base, draws in bases.items():
        ok = [c for c in draws if c.get("checks")]
        if len(draws) < 2 or not ok:
            continue
        ratios = [c["checks"]["sigma_ratio"] for c in ok if c["checks"]["sigma_ratio"]]
        worse = sum(1 for c in ok if c["checks"]["not_worse"] is False)
        nw = sum(1 for c in ok if c["flags"]["noise_weights"])
        warned = sum(1 for c in ok if c["checks"]["not_worse"] is False
                     and (c["report"].get("shape_warnings") or []))
        out.append(f"* {base} over {len(draws)} draws: worse than the input {worse} "
                   f"(with a shape warning {warned}), noise weights {nw}, sigma^/sigma "
                   f"{_f(min(ratios, default=None))} - {_f(max(ratios, default=None))}")
    return ["", *out] if out else []


def render(doc: dict[str, Any]) -> str:
    """The whole document."""
    cases = doc["cases"]
    halves = [h for h in HALVES if any(c["half"] == h for c in cases)]
    lines = ["# Issue 31: the default's misses on the new families", "",
             f"geosmooth commit {doc.get('commit')}; Taubin lambda {doc['taubin']['lambda']}, mu "
             f"{doc['taubin']['mu']}, {doc['taubin']['iterations']} iterations (trimesh on "
             f"meshes, Open3D k = {doc['cloud_knn']} on clouds, graph Laplacian on curves); "
             f"{doc['seconds']:.0f} s wall, load at the end "
             f"{', '.join(f'{x:.1f}' for x in doc['load_end'])}.", "",
             "Errors are fractions of the noisy input's (bulk points: strays excluded); 'auto' is "
             "the default with no smoothing parameter. Flags: NW per-point noise weights, out N "
             "points treated as outliers, flat 'the shape was flattened', moved 'moved more than "
             "removing the noise explains', no-noise 'no noise found'; '!' a false warning.", "",
             "## Targets", "", "| target | " + " | ".join(halves) + " |",
             "|---|" + "---|" * len(halves)]
    sums = {h: summary([c for c in cases if c["half"] == h]) for h in halves}
    for name in sums[halves[0]] if halves else []:
        lines.append(f"| {name} | " + " | ".join(sums[h][name] for h in halves) + " |")
    for half in halves:
        mine = [c for c in cases if c["half"] == half]
        lines += ["", f"## {half.capitalize()} half ({len(mine)} cases)"]
        for ph, title in TITLES.items():
            group = [c for c in mine if c["phenomenon"] == ph]
            if group:
                lines += ["", f"### {title}", "", HEADER, *(_row(c) for c in group),
                          *_draws(group)]
        clean = [c for c in mine if c["phenomenon"] == "clean"]
        if clean:
            lines += ["", "### Noise-free inputs", "", *_clean_rows(clean)]
    return "\n".join(lines) + "\n"
