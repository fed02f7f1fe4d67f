"""``python -m benchmarks [solvers|peers|all] [--quick] [--sizes ...] [--out DIR]``.

Prints markdown tables and writes ``<out>/<name>-<date>.json`` (name ``solvers`` or ``peers``,
with a ``-quick`` suffix for ``--quick``). The default run fits in about 10 minutes on a 2-core
machine; ``--quick`` in about one minute.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from benchmarks import report
from benchmarks.measure import machine_info
from benchmarks.shapes import SOLVER_SIZES
from benchmarks.solvers import DEFAULT_SIZES, QUICK_SIZES

__all__ = ["main"]


def _sizes(values: list[str] | None, quick: bool) -> list[str]:
    if not values:
        return list(QUICK_SIZES if quick else DEFAULT_SIZES)
    out = [s.strip().upper() for v in values for s in v.split(",") if s.strip()]
    bad = [s for s in out if s not in SOLVER_SIZES]
    if bad:
        raise SystemExit(f"unknown size(s) {', '.join(bad)}; choose from {', '.join(SOLVER_SIZES)}")
    return out


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def main(argv: list[str] | None = None) -> int:
    """Run the benchmarks; returns the exit code."""
    ap = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__.splitlines()[0])
    ap.add_argument("what", nargs="?", choices=("solvers", "peers", "all"), default="all")
    ap.add_argument("--quick", action="store_true", help="small sizes and sweeps (~1 min)")
    ap.add_argument(
        "--sizes",
        nargs="+",
        metavar="SIZE",
        help=f"solver-table sizes (default {','.join(DEFAULT_SIZES)}; "
        f"quick {','.join(QUICK_SIZES)}); any of {','.join(SOLVER_SIZES)}",
    )
    ap.add_argument(
        "--cap",
        type=float,
        default=None,
        help="seconds one non-CHOLMOD solver run may take (estimated) before it is skipped "
        "(default 90, quick 20)",
    )
    ap.add_argument(
        "--out",
        type=Path,
        default=Path(__file__).resolve().parent / "results",
        help="directory for the JSON results (default benchmarks/results)",
    )
    ap.add_argument("--no-json", action="store_true", help="print tables only")
    args = ap.parse_args(argv)
    sizes = _sizes(args.sizes, args.quick)
    cap = args.cap if args.cap is not None else (20.0 if args.quick else 90.0)
    suffix = "-quick" if args.quick else ""
    info = machine_info()
    t0 = time.perf_counter()
    print(f"# geosmooth benchmarks\n\n{report.machine_line(info)}\n")
    if args.what in ("solvers", "all"):
        from benchmarks.solvers import run_solvers

        _log("solvers ...")
        res = run_solvers(sizes, cap=cap, log=_log)
        res["machine"] = info
        res["quick"] = args.quick
        text = "## Solvers (report fig. 8)\n\n" + report.solver_tables(res)
        print(text + "\n")
        if not args.no_json:
            md = f"{report.machine_line(info)}\n\n{text}"
            _log(f"wrote {report.write_json(res, args.out, 'solvers' + suffix, md)}")
    if args.what in ("peers", "all"):
        from benchmarks.peers import run_peers

        _log("peers ...")
        res = run_peers(args.quick, log=_log)
        res["machine"] = info
        res["quick"] = args.quick
        inst = res["installed"]
        installed = ", ".join(
            f"{k} {v['version']}" if v["version"] else f"{k}: not installed ({v['error']})"
            for k, v in inst.items()
        )
        text = f"## Peers\n\nInstalled: {installed}\n\n{report.peers_tables(res)}"
        print(text + "\n")
        if not args.no_json:
            md = f"{report.machine_line(info)}\n\n{text}"
            _log(f"wrote {report.write_json(res, args.out, 'peers' + suffix, md)}")
    elapsed = time.perf_counter() - t0
    print(
        f"Total benchmark time: {elapsed:.0f} s; load average at end: "
        f"{' / '.join(f'{x:.2f}' for x in __import__('os').getloadavg())}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
