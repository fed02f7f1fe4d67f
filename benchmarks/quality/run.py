"""One benchmark case end to end: input, peers (cached), geosmooth's modes, the automatic tau."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from benchmarks.quality.cases import make_case
from benchmarks.quality.ours import modes_for, run_auto, run_mode
from benchmarks.quality.peers import QUALITY_PEERS
from benchmarks.quality.scores import Scorer
from benchmarks.quality.sweep import best_of, sweep_peer

__all__ = ["run_case", "write_tables"]

Log = Callable[[str], None]
METRICS = ("vertex", "surface")


def _peers(case: Any, scorer: Scorer, quick: bool, cache: Path | None, log: Log) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for peer in QUALITY_PEERS:
        if case.shape.kind not in peer.kinds:
            continue
        sweep = sweep_peer(case, peer, scorer, quick, cache, log)
        out[peer.name] = {
            "settings": len(sweep["rows"]),
            "error": sweep["error"],
            **{m: best_of(sweep["rows"], m) for m in METRICS},
        }
    return out


def run_case(
    key: str,
    *,
    quick: bool = False,
    cache: Path | None = None,
    modes: list[str] | None = None,
    peers: bool = True,
    ours: bool = True,
    log: Log = print,
) -> dict[str, Any]:
    """All measurements of one case (JSON-ready)."""
    t0 = time.perf_counter()
    case = make_case(key)
    scorer = Scorer(case)
    out: dict[str, Any] = {
        "key": key,
        "label": case.label,
        "kind": case.shape.kind,
        "n": case.n,
        "noise": case.noise,
        "level": case.level,
        "sigma": case.sigma,
        "source": case.shape.source,
        "input": scorer.full(case.points),
    }
    if peers:
        out["peers"] = _peers(case, scorer, quick, cache, log)
    if ours:
        out["modes"] = {name: run_mode(case, scorer, kw) for name, kw in
                        modes_for(case, modes).items()}
        out["auto"] = run_auto(case, scorer)
        out["gcv"] = run_auto(case, scorer, {"tau": "gcv"}, repeats=0) if case.n <= 12000 else None
    out["seconds"] = time.perf_counter() - t0
    return out


def write_tables(out: Path, stem: str, doc: dict[str, Any],
                 render: Callable[[dict[str, Any]], str]) -> str:
    """Write ``doc`` as ``out/stem.json`` and its rendering as ``out/stem.md``; the text."""
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{stem}.json").write_text(json.dumps(doc, indent=1, default=float))
    text = render(doc)
    (out / f"{stem}.md").write_text(text)
    return text
