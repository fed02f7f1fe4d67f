"""Markdown of one half (:mod:`benchmarks.quality.halves`): targets, cases, peers, wins/losses.

Definitions (errors are fractions of the noisy input's; "v" the RMS vertex error against the
clean positions, "s" the RMS distance to the true surface or curve):

* *auto*: geosmooth with no smoothing parameter (automatic tau);
* *own oracle*: the best of geosmooth's oracle modes, each at its best lambda per metric;
* *best peer (swept)*: the smallest error over every peer and every setting of its sweep;
* *best peer (defaults)*: the smallest error over the peers at their own defaults.
"""

from __future__ import annotations

import math
from collections import defaultdict
from typing import Any

from benchmarks.report import machine_line, markdown_table

__all__ = ["render", "targets"]

METRICS = ("vertex", "surface")
VERTEX_SLACK = 1.15
SIGMA_BAND = 0.15


def _f(x: float | None, d: int = 3) -> str:
    return "—" if x is None or not math.isfinite(x) else f"{x:.{d}f}"


def _val(row: dict[str, Any] | None, m: str) -> float | None:
    v = None if row is None else row.get(m)
    return None if v is None or not math.isfinite(v) else float(v)


def best_peer(c: dict[str, Any], m: str, which: str = "swept") -> tuple[str, float] | None:
    """(peer name, error) of the best peer on metric ``m`` (``swept`` or ``defaults``)."""
    rows = []
    for name, p in c.get("peers", {}).items():
        row = p["swept"].get(m) if which == "swept" else p.get("defaults")
        v = _val(row, m)
        if v is not None:
            rows.append((name, v))
    return min(rows, key=lambda r: r[1]) if rows else None


def best_mode(c: dict[str, Any], m: str) -> tuple[str, float] | None:
    rows = [(name, v) for name, mode in (c.get("modes") or {}).items()
            if isinstance(mode.get(m), dict) and (v := _val(mode[m], m)) is not None]
    return min(rows, key=lambda r: r[1]) if rows else None


def _sigma_ratio(c: dict[str, Any]) -> float | None:
    sig = ((c.get("auto") or {}).get("report") or {}).get("sigma_estimate")
    return float(sig) / c["sigma"] if sig is not None and c["sigma"] else None


def verdicts(c: dict[str, Any]) -> dict[str, bool | None]:
    """The issue's per-case targets (``None`` where they do not apply or were not measured)."""
    auto = c.get("auto") or {}
    av, asf = _val(auto, "vertex"), _val(auto, "surface")
    pv, ps = best_peer(c, "vertex"), best_peer(c, "surface")
    mv, ms = best_mode(c, "vertex"), best_mode(c, "surface")
    sr = _sigma_ratio(c)
    flips_in, flips = c["input"].get("flipped"), auto.get("flipped")
    if "modes" in c and not auto:  # geosmooth ran and the default failed: every auto target
        failed: dict[str, bool | None] = {k: False for k, _, _ in TARGETS}
        return {**failed, "best_le_peer_v": None if mv is None or pv is None else mv[1] <= pv[1],
                "best_le_peer_s": None if ms is None or ps is None else ms[1] <= ps[1]}
    return {
        "auto_le_peer_s": None if asf is None or ps is None else asf <= ps[1],
        "auto_115_peer_v": None if av is None or pv is None else av <= VERTEX_SLACK * pv[1],
        "best_le_peer_v": None if mv is None or pv is None else mv[1] <= pv[1],
        "best_le_peer_s": None if ms is None or ps is None else ms[1] <= ps[1],
        "not_worse": None if av is None or asf is None else av <= 1.0 and asf <= 1.0,
        "sigma_15": None if sr is None else abs(sr - 1.0) <= SIGMA_BAND,
        "flips_le_input": None if flips is None or flips_in is None else flips <= flips_in,
    }


TARGETS = [
    ("auto_le_peer_s", "automatic tau <= best peer's swept best, distance to the true surface",
     ">= 80 %"),
    ("auto_115_peer_v", "automatic tau within 1.15x of the best peer's swept best, vertex error",
     "all"),
    ("best_le_peer_v", "geosmooth's best mode at its oracle <= best peer's swept best, vertex",
     "all"),
    ("best_le_peer_s", "geosmooth's best mode at its oracle <= best peer's swept best, surface",
     "all"),
    ("not_worse", "automatic tau never worse than the input (vertex and surface <= 1)", "all"),
    ("sigma_15", "sigma^ within +-15 % of the true noise level", ">= 90 %"),
    ("flips_le_input", "flipped faces at the automatic tau <= the input's (meshes, grids)",
     "all"),
]


def targets(doc: dict[str, Any]) -> dict[str, tuple[int, int]]:
    """Per target: (cases meeting it, cases where it applies)."""
    out: dict[str, tuple[int, int]] = {}
    vs = [verdicts(c) for c in doc["cases"]]
    for key, _, _ in TARGETS:
        got = [v[key] for v in vs if v[key] is not None]
        out[key] = (sum(bool(g) for g in got), len(got))
    return out


def _target_lines(doc: dict[str, Any]) -> list[str]:
    t = targets(doc)
    rows = []
    for key, text, goal in TARGETS:
        k, n = t[key]
        rows.append([text, f"{k}/{n}" + (f" ({100 * k / n:.0f} %)" if n else ""), goal])
    return [markdown_table(["target", "cases", "goal"], rows)]


def _case_row(c: dict[str, Any]) -> list[str]:
    auto = c.get("auto") or {}
    cells = [c["key"], c["kind"], f"{c['n']:,}"]
    for m in METRICS:
        cells.append(_f(_val(auto, m)) if c.get("auto") else "failed" if c.get("error") else "—")
    for m in METRICS:
        b = best_mode(c, m)
        cells.append(f"{_f(b[1])} ({b[0]})" if b else "—")
    for which in ("swept", "defaults"):
        for m in METRICS:
            p = best_peer(c, m, which)
            cells.append(f"{_f(p[1])} ({p[0]})" if p else "—")
    sr = _sigma_ratio(c)
    cells.append(_f(sr, 2))
    flips = auto.get("flipped")
    cells.append("—" if flips is None else f"{flips} / {c['input'].get('flipped')}")
    return cells


def _peer_rows(c: dict[str, Any]) -> list[list[str]]:
    rows = []
    for name, p in c.get("peers", {}).items():
        sw, df = p["swept"], p.get("defaults")
        note = p.get("error") or p.get("defaults_error") or ""
        rows.append([c["key"], name, _f(_val(sw.get("vertex"), "vertex")),
                     _f(_val(sw.get("surface"), "surface")), _f(_val(df, "vertex")),
                     _f(_val(df, "surface")), "—" if df is None or df.get("flipped") is None
                     else str(df["flipped"]), note[:60]])
    return rows


def _groups(doc: dict[str, Any], field: str) -> list[list[str]]:
    acc: dict[str, list[dict[str, bool | None]]] = defaultdict(list)
    for c in doc["cases"]:
        acc[c[field]].append(verdicts(c))
    rows = []
    for name in sorted(acc):
        cells = [name, str(len(acc[name]))]
        for key in ("auto_le_peer_s", "auto_115_peer_v", "best_le_peer_v", "best_le_peer_s",
                    "not_worse"):
            got = [v[key] for v in acc[name] if v[key] is not None]
            cells.append(f"{sum(bool(g) for g in got)} / {sum(not g for g in got)}")
        rows.append(cells)
    return rows


def _modes(modes: list[str] | dict[str, list[str]]) -> str:
    if isinstance(modes, dict):
        return "; ".join(f"{kind}: " + ", ".join(names) for kind, names in modes.items())
    return ", ".join(modes)


def render(doc: dict[str, Any]) -> str:
    """The dated markdown document of one half."""
    peers = ", ".join(f"{k} {v}" if v else f"{k} (not installed)" for k, v in doc["peers"].items())
    header = ["case", "kind", "n", "auto v", "auto s", "own oracle v", "own oracle s",
              "best peer swept v", "best peer swept s", "best peer defaults v",
              "best peer defaults s", "σ̂/σ", "flips auto / input"]
    group_head = ["", "cases", "auto ≤ peer (s) W / L", "auto ≤ 1.15 peer (v) W / L",
                  "best mode ≤ peer (v) W / L", "best mode ≤ peer (s) W / L",
                  "auto ≤ input W / L"]
    parts = [
        f"# geosmooth quality: the {doc['half']} half of issue 21's families",
        "",
        machine_line(doc["machine"]) + "; load at end "
        + " / ".join(f"{x:.2f}" for x in doc["load_end"]),
        "",
        f"Peers: {peers}. Whole run {doc['seconds']:.0f} s. geosmooth's oracle modes: "
        + _modes(doc["modes"]) + f" (decade scan +-{doc.get('decades', 2)} decades around "
        f"the automatic lambda, {doc['refine']} parabolic steps per metric). The split "
        "(calibration / test by family, fixed) is `benchmarks/quality/families.py: SPLIT`.",
        "",
        "Errors are fractions of the noisy input's: v = RMS vertex error against the clean "
        "positions, s = RMS distance to the true surface or curve. 'auto': no smoothing "
        "parameter. 'own oracle': geosmooth's best mode at its best lambda. Peers: the best over "
        "every peer's sweep ('swept', an oracle no user has) and over the peers at their own "
        "defaults ('defaults', what a user gets).",
        "",
        "## Targets (issue 21)",
        "",
        *_target_lines(doc),
        "",
        "## Cases",
        "",
        markdown_table(header, [_case_row(c) for c in doc["cases"]]),
        "",
        "## Wins / losses by noise model",
        "",
        markdown_table(["noise", *group_head[1:]], _groups(doc, "noise")),
        "",
        "## Wins / losses by shape",
        "",
        markdown_table(["shape", *group_head[1:]], _groups(doc, "shape")),
        "",
        "## Every peer: swept best and defaults",
        "",
        markdown_table(["case", "peer", "swept v", "swept s", "defaults v", "defaults s",
                        "defaults flips", "note"],
                       [r for c in doc["cases"] for r in _peer_rows(c)]),
        "",
    ]
    return "\n".join(parts)
