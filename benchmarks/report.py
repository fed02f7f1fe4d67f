"""Markdown tables and JSON files of benchmark results."""

from __future__ import annotations

import datetime as _dt
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from benchmarks.solvers import REPORT_FIG8

__all__ = [
    "machine_line",
    "markdown_table",
    "peers_tables",
    "solver_tables",
    "write_json",
]


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A GitHub-flavoured markdown table (first column left-aligned, the rest right-aligned)."""
    align = [":---"] + ["---:"] * (len(header) - 1)
    lines = ["| " + " | ".join(header) + " |", "| " + " | ".join(align) + " |"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def _num(x: float | None, digits: int = 3) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "—"
    if x == 0:
        return "0"
    ax = abs(x)
    if ax >= 1000:
        return f"{x:,.0f}"
    if ax >= 0.01:
        return f"{x:.{digits}g}" if ax < 100 else f"{x:.0f}"
    return f"{x:.{digits}g}"


def _sec(x: float | None) -> str:
    if x is None:
        return "—"
    return f"{x:.3f}" if x < 1 else f"{x:.2f}" if x < 100 else f"{x:.0f}"


def machine_line(info: dict[str, Any]) -> str:
    """One line: date, CPU, cores, memory, OS, Python, BLAS, load average."""
    load = info.get("load_average") or []
    return (
        f"{info['date']} — {info['cpu']}, {info['cores']} cores, {info['memory_gib']} GiB RAM, "
        f"{info['os']}, Python {info['python']}, system BLAS {info['system_blas']}, "
        f"load average at start {' / '.join(str(x) for x in load)}"
    )


# --- solvers ---------------------------------------------------------------------------------


def _cell(row: dict[str, Any] | None, value: str) -> str:
    if row is None:
        return "—"
    if row["status"] == "ok":
        return value
    reason = row.get("reason", "")
    return f"—({row['status']}: {reason})" if reason else f"—({row['status']})"


def solver_tables(result: dict[str, Any]) -> str:
    """The fig. 8 table (speedups of CHOLMOD) and the per-solver detail table."""
    by: dict[tuple[str, str], dict[str, Any]] = {
        (r["size"], r["solver"]): r for r in result["rows"]
    }
    main_rows = []
    for case in result["sizes"]:
        size = case["size"]
        ch = by.get((size, "cholmod"))
        t_ch = ch["total"] if ch and ch["status"] == "ok" else None

        def speedup(solver: str, size: str = size, t_ch: float | None = t_ch, ch: Any = ch) -> str:
            r = by.get((size, solver))
            if r is None or t_ch is None:
                return "—"
            if r["status"] != "ok":
                return _cell(r, "")
            return f"{r['total'] / t_ch:.1f} ({r['per_lambda'] / ch['per_lambda']:.1f})"

        rep = REPORT_FIG8.get(size)
        main_rows.append(
            [
                size,
                case["name"],
                f"{case['n']:,}",
                speedup("umfpack"),
                speedup("spqr"),
                speedup("superlu"),
                _cell(ch, _sec(t_ch)),
                *((f"{rep[0]:.1f}", f"{rep[1]:.1f}", f"{rep[2]:.2f}") if rep else ("—", "—", "—")),
            ]
        )
    main = markdown_table(
        [
            "size",
            "mesh",
            "points",
            "speedup vs UMFPACK",
            "speedup vs sparse QR",
            "speedup vs SuperLU",
            "time CHOLMOD (s)",
            "report: vs UMFPACK",
            "report: vs sparse QR",
            "report: time CHOLMOD (s)",
        ],
        main_rows,
    )
    detail_rows = []
    for r in result["rows"]:
        ok = r["status"] == "ok"
        detail_rows.append(
            [
                r["size"],
                r["solver"],
                _cell(r, str(r.get("iterations", ""))),
                _cell(r, str(r.get("factorizations", ""))) if ok else "",
                _sec(r.get("total")) if ok else "",
                _sec(r.get("build")) if ok else "",
                (_sec(r.get("analysis")) if r["solver"] != "spqr" else "(per QR)") if ok else "",
                _sec(r.get("factorization_mean")) if ok else "",
                (_sec(r.get("solve")) if r["solver"] != "spqr" else "(in QR)") if ok else "",
                _num(r.get("peak_rss_mb"), 4) if ok else "",
                _num(r.get("rss_before_mb"), 4) if ok else "",
                _num(r.get("phi_rel_diff"), 2) if ok and "phi_rel_diff" in r else "",
            ]
        )
    detail = markdown_table(
        [
            "size",
            "solver",
            "λ iterations",
            "factorizations",
            "total (s)",
            "build L (s)",
            "symbolic analysis (s)",
            "one numeric factorization (s)",
            "all solves (s)",
            "peak RSS (MiB)",
            "RSS before solving (MiB)",
            "max rel. φ diff vs CHOLMOD",
        ],
        detail_rows,
    )
    legend = (
        "Speedup = (time of the whole tau-constrained smoothing with that solver) / (time with "
        "CHOLMOD), same lambda sequence and number of factorizations; in brackets the same ratio "
        "for the numeric work per lambda only (one factorization + one solve; SPQR: one QR "
        "solve). Report columns: Matlab 7, 2.4 GHz Pentium 4 (report fig. 8). Peak RSS is each "
        "solver's own process (VmHWM), interpreter and input included. Runs under 1 s: best of 3."
    )
    sources = "\n".join(
        f"- **{c['size']}**: {c['source']}; τ = {c['tau']:.4g}" for c in result["sizes"]
    )
    return f"{main}\n\n{legend}\n\n{detail}\n\nInputs:\n{sources}"


# --- peers -----------------------------------------------------------------------------------


def _pct(x: float | None) -> str:
    return "—" if x is None else f"{x:+.2f}"


def peers_tables(result: dict[str, Any]) -> str:
    """One table per case, then a summary table."""
    parts = []
    summary = []
    for case in result["cases"]:
        rows = []
        for r in case["rows"]:
            o = r.get("ours_same_tau") or {}
            if r["error"] is None:
                rows.append(
                    [r["method"], r["setting"], "—", "—", "—", "—", "—", "—", "—"]
                    if not r.get("note")
                    else [r["method"], f"{r['setting']} ({r['note']})", *["—"] * 7]
                )
                continue
            rows.append(
                [
                    r["method"],
                    r["setting"] + (f" ({r['note']})" if r.get("note") else ""),
                    _num(r["error"]),
                    _sec(r["time"]) if r["time"] else "—",
                    _pct(r["volume_change"]),
                    _num(r["deviation"]),
                    _num(o.get("error")) if o else "—",
                    _sec(o.get("time")) if o.get("time") else "—",
                    _pct(o.get("volume_change")) if o else "—",
                ]
            )
        head = (
            f"**{case['case']}** — {case['n']:,} points, {case['source']}; "
            f"noise energy τ = {case['tau_noise']:.4g}"
            + (f"; peer sweep grid: {case['peer_grid']}" if case["kind"] == "mesh" else "")
        )
        vol = "area Δ %" if case["kind"] == "curve" else "volume Δ %"
        parts.append(
            head
            + "\n\n"
            + markdown_table(
                [
                    "method",
                    "best setting",
                    "RMS error",
                    "time (s)",
                    vol,
                    "RMS ‖x−p‖",
                    "ours @ same τ: RMS error",
                    "ours: time (s)",
                    f"ours: {vol}",
                ],
                rows,
            )
        )
        summary.append(_summary_row(case))
    table = markdown_table(
        [
            "input",
            "points",
            "noisy input",
            "best peer (RMS error)",
            "ours @ that peer's τ",
            "ours, τ = noise energy",
            "ours, τ = n·σ² (normal noise)",
            "ours, uniform weights, τ = noise",
            "ours, best τ of sweep",
        ],
        summary,
    )
    return (
        "Summary (RMS distance to the ground-truth surface/curve):\n\n"
        + table
        + "\n\n"
        + ("\n\n".join(parts))
    )


def _summary_row(case: dict[str, Any]) -> list[str]:
    rows = case["rows"]
    peers = [r for r in rows if r["error"] is not None and r["ours_same_tau"] is not None]
    best = min(peers, key=lambda r: r["error"]) if peers else None

    def ours(method: str, setting: str) -> str:
        for r in rows:
            if r["method"] == method and r["setting"] == setting and r["error"] is not None:
                return _num(r["error"])
        return "n/a"

    best_sweep = next((r for r in rows if r["method"] == "ours, best tau of sweep"), None)
    return [
        case["case"],
        f"{case['n']:,}",
        _num(rows[0]["error"]),
        f"{_num(best['error'])} ({best['method']})" if best else "n/a (no peer handles it)",
        _num(best["ours_same_tau"].get("error")) if best else "n/a",
        ours("ours, tau = noise energy", "defaults"),
        ours("ours, tau = normal noise n*sigma^2", "defaults"),
        ours("ours, tau = noise energy", "weights=uniform"),
        f"{_num(best_sweep['error'])} ({best_sweep['setting']})" if best_sweep else "n/a",
    ]


def write_json(
    result: dict[str, Any], out_dir: Path, name: str, markdown: str | None = None
) -> Path:
    """Write ``<out_dir>/<name>-<YYYY-MM-DD>.json`` (and ``.md`` with ``markdown``).

    Returns
    -------
    Path
        The JSON file.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    date = _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d")
    path = out_dir / f"{name}-{date}.json"
    path.write_text(json.dumps(result, indent=1, default=_default) + "\n")
    if markdown is not None:
        path.with_suffix(".md").write_text(markdown.rstrip() + "\n")
    return path


def _default(obj: Any) -> Any:
    if hasattr(obj, "tolist"):
        return obj.tolist()
    if hasattr(obj, "item"):
        return obj.item()
    raise TypeError(f"not JSON serializable: {type(obj).__name__}")
