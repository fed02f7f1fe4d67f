"""``python -m benchmarks.quality [--quick] [--cases KEY ...] [--peers-only] [--out DIR]``.

Runs the quality benchmark (ground truth, peers' best over their sweeps, geosmooth's modes at
their oracle tau and with the automatic tau) and writes one dated table,
``<out>/quality-<date>.md``, with the raw numbers in ``quality-<date>.json`` beside it (suffix
``-quick`` for ``--quick``). Peer sweeps are cached per case in ``<out>/cache/`` (they do not
depend on geosmooth), so a re-run only redoes geosmooth. Run it with ``nice``: the full run
takes about an hour on two shared cores with an empty cache, ``--quick`` a few minutes.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import sys
import time
from pathlib import Path

from benchmarks.measure import machine_info
from benchmarks.quality.cases import FULL, QUICK
from benchmarks.quality.peers import peer_versions
from benchmarks.quality.run import run_case, write_tables
from benchmarks.quality.table import render

RESULTS = Path(__file__).resolve().parent / "results"


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def main(argv: list[str] | None = None) -> int:
    """Run the quality benchmark; returns the exit status."""
    ap = argparse.ArgumentParser(prog="python -m benchmarks.quality", description=__doc__)
    ap.add_argument("--quick", action="store_true", help="8 cases, small peer grids")
    ap.add_argument("--cases", nargs="+", metavar="KEY", help="case keys (see cases.py)")
    ap.add_argument("--peers-only", action="store_true", help="fill the peer cache only")
    ap.add_argument("--modes", nargs="+", help="geosmooth modes to run (default: all)")
    ap.add_argument("--out", type=Path, default=RESULTS, help="results directory")
    args = ap.parse_args(argv)
    keys = args.cases or (QUICK if args.quick else FULL)
    cache = args.out / "cache"
    info = machine_info()
    t0 = time.perf_counter()
    results = []
    for i, key in enumerate(keys, 1):
        _log(f"[{i}/{len(keys)}] {key}")
        r = run_case(key, quick=args.quick, cache=cache, modes=args.modes,
                     ours=not args.peers_only, log=_log)
        results.append(r)
        _log(f"    {r['seconds']:.1f} s")
        if not args.peers_only:  # keep what is done if the run is interrupted
            args.out.mkdir(parents=True, exist_ok=True)
            (args.out / "quality-partial.json").write_text(json.dumps(results, default=float))
    if args.peers_only:
        return 0
    doc = {"machine": info, "peers": peer_versions(), "quick": args.quick, "cases": results,
           "seconds": time.perf_counter() - t0, "load_end": list(os.getloadavg())}
    day = dt.datetime.now(dt.UTC).strftime("%Y-%m-%d")
    stem = f"quality-{day}" + ("-quick" if args.quick else "")
    print(write_tables(args.out, stem, doc, render))
    _log(f"wrote {args.out / stem}.md and .json ({doc['seconds']:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
