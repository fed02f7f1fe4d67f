"""The quality benchmark's markdown: targets summary, one row per case, mode and peer winners."""

from __future__ import annotations

import math
from collections import Counter
from typing import Any

from benchmarks.report import machine_line, markdown_table

__all__ = ["render", "summary"]

METRICS = ("vertex", "surface")
SMOOTH_SHAPES = ("sphere", "torus", "spot", "bun_zipper", "horse")


def _f(x: float | None, d: int = 3) -> str:
    return "—" if x is None or not math.isfinite(x) else f"{x:.{d}f}"


def _best_peer(case: dict[str, Any], metric: str) -> tuple[str, dict[str, Any]] | None:
    rows = [(name, p[metric]) for name, p in case.get("peers", {}).items() if p.get(metric)]
    return min(rows, key=lambda r: r[1][metric]) if rows else None


def _best_mode(case: dict[str, Any], metric: str) -> tuple[str, dict[str, Any]] | None:
    rows = [(name, m[metric]) for name, m in case.get("modes", {}).items() if m.get(metric)]
    return min(rows, key=lambda r: r[1][metric]) if rows else None


def _default_oracle(case: dict[str, Any], metric: str) -> float | None:
    m = case.get("modes", {}).get("default", {}).get(metric)
    return m[metric] if m else None


def summary(doc: dict[str, Any]) -> dict[str, Any]:
    """Counts of the issue's targets over the cases."""
    out: Counter[str] = Counter()
    n = 0
    costs, flips = [], []
    for c in doc["cases"]:
        n += 1
        auto = c.get("auto") or {}
        for m in METRICS:
            peer, mode = _best_peer(c, m), _best_mode(c, m)
            if peer is None:
                out[f"no_peer_{m}"] += 1
            if peer is None or (mode and mode[1][m] <= peer[1][m]):
                out[f"best_le_peer_{m}"] += 1
            orc = _default_oracle(c, m)
            if auto.get(m) is not None and orc and auto[m] <= 1.15 * orc:
                out[f"auto_le_115_{m}"] += 1
            if auto.get(m) is not None and (peer is None or auto[m] <= peer[1][m]):
                out[f"auto_le_peer_{m}"] += 1
        sig = (auto.get("report") or {}).get("sigma_estimate")
        if sig and abs(sig / c["sigma"] - 1) <= 0.15:
            out["sigma_15"] += 1
        if auto.get("cost_ratio"):
            costs.append(auto["cost_ratio"])
        if c["kind"] == "mesh" and c["key"].startswith(SMOOTH_SHAPES) and c["noise"] != "outliers":
            flips.append((auto.get("flipped") or 0) > (c["input"].get("flipped") or 0))
    costs.sort()
    return {
        "cases": n,
        **out,
        "cost_median": costs[len(costs) // 2] if costs else None,
        "cost_max": costs[-1] if costs else None,
        "smooth_meshes": len(flips),
        "smooth_meshes_with_flips": sum(flips),
    }


def _summary_lines(s: dict[str, Any]) -> list[str]:
    n = s["cases"]

    def frac(key: str) -> str:
        return f"{s.get(key, 0)}/{n} ({100 * s.get(key, 0) / max(n, 1):.0f} %)"

    return [
        f"- geosmooth's best mode <= best peer's best: vertex error {frac('best_le_peer_vertex')},"
        f" distance to the true surface {frac('best_le_peer_surface')} (target: all).",
        f"- automatic tau <= 1.15 x the default mode's oracle tau: vertex "
        f"{frac('auto_le_115_vertex')}, surface {frac('auto_le_115_surface')} (target: all).",
        f"- automatic tau <= best peer's oracle-best: vertex {frac('auto_le_peer_vertex')}, "
        f"surface {frac('auto_le_peer_surface')} (target: >= 80 %).",
        f"- sigma estimate within +-15 %: {frac('sigma_15')} (target: >= 90 %).",
        f"- cost of the automatic tau / the same run with that tau given: median "
        f"{_f(s['cost_median'], 2)}, max {_f(s['cost_max'], 2)} (target: <= 1.5).",
        f"- smooth meshes with more flipped faces (against the clean mesh) at the automatic tau "
        f"than in the noisy input: {s['smooth_meshes_with_flips']}/{s['smooth_meshes']} "
        "(target: none).",
    ]


def _row(c: dict[str, Any]) -> list[str]:
    auto = c.get("auto") or {}
    cells = [c["key"], f"{c['n']:,}"]
    for m in METRICS:
        p = _best_peer(c, m)
        cells.append(f"{_f(p[1][m])} ({p[0]})" if p else "n/a")
    for m in METRICS:
        b = _best_mode(c, m)
        cells.append(f"{_f(b[1][m])} ({b[0]})" if b else "—")
    for m in METRICS:
        orc = _default_oracle(c, m)
        a = auto.get(m)
        cells.append(f"{_f(a)} ({_f(a / orc, 2) if a and orc else '—'}x)")
    gcv = c.get("gcv") or {}
    cells.append(f"{_f(gcv.get('vertex'))} / {_f(gcv.get('surface'))}" if gcv else "—")
    sig = (auto.get("report") or {}).get("sigma_estimate")
    cells.append(_f(sig / c["sigma"], 2) if sig else "—")
    flips = auto.get("flipped")
    cells.append("—" if flips is None else f"{flips} / {c['input'].get('flipped')}")
    cells.append(_f(auto.get("cost_ratio"), 2))
    return cells


def _wins(doc: dict[str, Any]) -> list[str]:
    lines = []
    for m in METRICS:
        modes = Counter(b[0] for c in doc["cases"] if (b := _best_mode(c, m)))
        peers = Counter(p[0] for c in doc["cases"] if (p := _best_peer(c, m)))
        lines.append(f"- best geosmooth mode ({m}): "
                     + ", ".join(f"{k} {v}" for k, v in modes.most_common()))
        lines.append(f"- best peer ({m}): " + ", ".join(f"{k} {v}" for k, v in peers.most_common()))
    return lines


def render(doc: dict[str, Any]) -> str:
    """The dated markdown document of one run."""
    s = summary(doc)
    peers = ", ".join(f"{k} {v}" if v else f"{k} (not installed)" for k, v in doc["peers"].items())
    header = [
        "case", "n", "best peer: vertex", "best peer: surface", "geosmooth best: vertex",
        "geosmooth best: surface", "auto: vertex (x oracle)", "auto: surface (x oracle)",
        "gcv: vertex / surface", "sigma^/sigma", "flips: auto / input", "auto cost",
    ]
    parts = [
        f"# geosmooth quality benchmark{' (quick)' if doc['quick'] else ''}",
        "",
        machine_line(doc["machine"]) + "; load at end "
        + " / ".join(f"{x:.2f}" for x in doc["load_end"]),
        "",
        f"Peers: {peers}. Whole run {doc['seconds']:.0f} s "
        "(`nice -n 10 python -m benchmarks.quality`; peer sweeps cached in results/cache).",
        "",
        "Errors are fractions of the noisy input's: RMS vertex error against the clean positions"
        " ('vertex') and RMS distance to the true surface or curve ('surface'). Peers and "
        "geosmooth's modes: best over their sweep (an oracle choice). 'auto': geosmooth with no "
        "smoothing parameter at all, and its ratio to the default mode at its oracle tau.",
        "",
        "## Targets",
        "",
        *_summary_lines(s),
        "",
        "## Cases",
        "",
        markdown_table(header, [_row(c) for c in doc["cases"]]),
        "",
        "## Who wins",
        "",
        *_wins(doc),
        "",
    ]
    return "\n".join(parts)
