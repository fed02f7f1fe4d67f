"""``python -m benchmarks.speed [counts|sizes|all] [--quick] [--out DIR]`` (issue 8).

* ``counts``: every job kind (meshes, torus, curves, clouds, real meshes; light to heavy tau;
  fixed points, per-point weights, L(kappa), L(f), order 2) on the ``auto`` path: numeric
  factorizations, solves, products with L^T L, |phi - tau| / tau, and the ratio of the whole
  tau-constrained smoothing to one analysis + factorization + solve at the lambda found.
* ``sizes``: icospheres 10K..655K and a 1M-vertex torus on every path (auto, direct, cg,
  windowed-sinc) with stage times, peak RSS, error against the noise-free mesh, Open3D's
  Laplacian filter (10 iterations) on the same mesh in the same process, and the growth
  exponents of time and memory in n per path.

Each job runs in a fresh interpreter (its own peak RSS). Results: ``<out>/speed-<date>.json``
and ``.md`` with the machine and its load. ``--quick`` is the smoke size (one small job per path).
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.measure import machine_info
from benchmarks.speed.jobs import jobs

__all__ = ["growth", "main", "run"]

PATHS = ("auto", "direct", "cg", "windowed-sinc")


def _child(spec: dict[str, Any], timeout: float) -> dict[str, Any]:
    with tempfile.TemporaryDirectory() as tmp:
        spec_path, out_path = Path(tmp) / "spec.json", Path(tmp) / "out.json"
        spec_path.write_text(json.dumps(spec))
        root = Path(__file__).resolve().parents[2]
        env = {
            **os.environ,
            "PYTHONPATH": str(root) + os.pathsep + os.environ.get("PYTHONPATH", ""),
        }
        cmd = [sys.executable, "-m", "benchmarks.speed.child", str(spec_path), str(out_path)]
        try:
            done = subprocess.run(cmd, cwd=root, env=env, capture_output=True, text=True,
                                  timeout=timeout, check=False)  # fmt: skip
        except subprocess.TimeoutExpired:
            return {"name": spec["job"]["name"], "path": spec["path"], "status": "timeout"}
        if done.returncode != 0 or not out_path.is_file():
            tail = (done.stderr.strip().splitlines() or ["?"])[-1]
            return {"name": spec["job"]["name"], "path": spec["path"], "status": f"error: {tail}"}
        return {**json.loads(out_path.read_text()), "status": "ok"}


def run(which: str, quick: bool, timeout: float, log: Any) -> list[dict[str, Any]]:
    """Run the job set ``which`` ("counts" or "sizes"); one row per job and path."""
    rows = []
    if which == "counts":
        specs = [{"job": vars(j), "path": "auto"} for j in jobs("tiny" if quick else "counts")]
    else:
        sizes = jobs("sizes")[:1] if quick else jobs("sizes")
        specs = [{"job": vars(j), "path": p, "open3d": True} for j in sizes for p in PATHS]
    for spec in specs:
        t0 = time.perf_counter()
        row = _child(spec, timeout)
        seconds = time.perf_counter() - t0
        log(f"{row['name']:40s} {row['path']:14s} {row.get('status')} {seconds:.1f}s")
        rows.append(row)
    return rows


def growth(rows: list[dict[str, Any]], key: str) -> dict[str, float]:
    """Least-squares exponent ``b`` of ``key ~ n^b`` per path over the ``sizes`` rows."""
    out = {}
    for path in PATHS:
        pts = [(r["n"], r[key]) for r in rows if r.get("status") == "ok" and r["path"] == path]
        if len(pts) >= 2:
            x, y = np.log([p[0] for p in pts]), np.log([max(p[1], 1e-9) for p in pts])
            out[path] = float(np.polyfit(x, y, 1)[0])
    return out


def _fmt(v: Any, spec: str = ".3g") -> str:
    return "—" if v is None else format(v, spec) if isinstance(v, float) else str(v)


def _count_rows(counts: list[dict[str, Any]]) -> list[str]:
    ok = [r for r in counts if r.get("status") == "ok"]
    fac = [r["factorizations"] for r in ok]
    ratios = [r["ratio_one"] for r in ok if r["solver"] == "cholmod"]
    worst = max((r["relative_error"] or 0.0) for r in ok) if ok else None
    lines = [
        "### Work per job (auto path)\n",
        f"{len(ok)}/{len(counts)} jobs ok; numeric factorizations median "
        f"{_fmt(float(np.median(fac)) if fac else None)}, max {max(fac) if fac else '—'}; "
        f"max |phi - tau|/tau {_fmt(worst)}; whole / one direct solve at lambda*: median "
        f"{_fmt(float(np.median(ratios)) if ratios else None)} (direct-path jobs)\n",
        "| job | n | lambda | fact. | solves | products | rel. error | whole / one solve "
        "| solver |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in counts:
        if r.get("status") != "ok":
            lines.append(f"| {r['name']} | {r.get('status')} |||||||")
            continue
        lines.append(
            f"| {r['name']} | {r['n']} | {_fmt(r['lam'])} | {r['factorizations']} | "
            f"{r['solves']} | {r['matvecs']} | {_fmt(r['relative_error'], '.1e')} | "
            f"{_fmt(r['ratio_one'], '.2f')} | {r['solver']} |"
        )
    return lines


def _size_rows(sizes: list[dict[str, Any]]) -> list[str]:
    lines = [
        "\n### Sizes and paths (rms = sigma; seconds; error = RMS vertex error to the "
        "noise-free mesh)\n",
        "| mesh | n | path | build | search+solve | whole / one solve | fact. | products "
        "| peak RSS MiB | MiB per 1M points | error (input) | Open3D s | Open3D error "
        "| ours+build / Open3D |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in sizes:
        if r.get("status") != "ok":
            lines.append(f"| {r['name']} | | {r['path']} | {r.get('status')} |||||||||||")
            continue
        cells = [
            r["name"].split("/")[0], r["n"], r["path"], _fmt(r["build"], ".2f"),
            _fmt(r["whole"], ".2f"), _fmt(r["ratio_one"], ".2f"), r["factorizations"],
            r["matvecs"], f"{r['rss_mb']:.0f}", f"{r['rss_mb'] / r['n'] * 1e6:.0f}",
            f"{_fmt(r['error_ours'], '.2e')} ({_fmt(r['error_input'], '.2e')})",
            _fmt(r.get("open3d_seconds"), ".2f"), _fmt(r.get("error_open3d"), ".2e"),
            _fmt(r.get("ratio_open3d"), ".1f"),
        ]  # fmt: skip
        lines.append("| " + " | ".join(str(c) for c in cells) + " |")
    t, m = growth(sizes, "whole"), growth(sizes, "rss_mb")
    lines += ["\nGrowth exponents b (time or memory ~ n^b) per path:\n"]
    lines += ["| path | time | memory |", "|---|---|---|"]
    lines += [f"| {p} | {_fmt(t.get(p), '.2f')} | {_fmt(m.get(p), '.2f')} |" for p in PATHS]
    return lines


def tables(counts: list[dict[str, Any]], sizes: list[dict[str, Any]]) -> str:
    """Markdown tables of both sets."""
    return "\n".join((_count_rows(counts) if counts else []) + (_size_rows(sizes) if sizes else []))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.speed", description=__doc__.splitlines()[0]
    )
    ap.add_argument("what", nargs="?", choices=("counts", "sizes", "all"), default="all")
    ap.add_argument("--quick", action="store_true", help="smoke size: a few small jobs")
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds per job")
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parent / "results")
    ap.add_argument("--no-json", action="store_true", help="print the tables only")
    args = ap.parse_args(argv)
    info = machine_info()
    log = lambda msg: print(msg, file=sys.stderr, flush=True)  # noqa: E731
    counts = run("counts", args.quick, args.timeout, log) if args.what in ("counts", "all") else []
    sizes = run("sizes", args.quick, args.timeout, log) if args.what in ("sizes", "all") else []
    info["load_average_end"] = [round(x, 2) for x in os.getloadavg()]
    head = (f"{info['date']}, {info['cpu']}, {info['cores']} cores, load {info['load_average']} "
            f"at start and {info['load_average_end']} at the end")  # fmt: skip
    text = f"{head}\n\n{tables(counts, sizes)}\n"
    print(text)
    if not args.no_json:
        args.out.mkdir(parents=True, exist_ok=True)
        stem = f"speed-{_dt.date.today().isoformat()}{'-quick' if args.quick else ''}"
        (args.out / f"{stem}.json").write_text(
            json.dumps({"machine": info, "counts": counts, "sizes": sizes}, indent=1)
        )
        (args.out / f"{stem}.md").write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
