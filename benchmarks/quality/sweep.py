"""Parameter sweeps: every peer over its grid (cached per case), geosmooth over lambda.

A peer's score is its best result over its sweep, selected separately for the vertex error and
for the distance to the true surface (an oracle choice no user can make). geosmooth's oracle is
the same: for each mode, the lambda (equivalently the tau = phi(lambda)) with the smallest error,
found by a coarse scan of log lambda refined by golden-section search.
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.quality.cases import Case
from benchmarks.quality.peers import QualityPeer, peer_versions, run_isolated
from benchmarks.quality.scores import Scorer

__all__ = ["best_of", "lambda_oracle", "sweep_peer"]

Log = Callable[[str], None]
CACHE_VERSION = 1


def _setting_str(s: dict[str, Any]) -> str:
    return ", ".join(f"{k}={v}" for k, v in s.items())


def _cache_file(cache_dir: Path, case: Case, peer: QualityPeer, quick: bool) -> Path:
    versions = peer_versions()
    key = [CACHE_VERSION, case.key, peer.name, quick, versions.get(peer.package)]
    tag = json.dumps([*key, peer.revision] if peer.revision else key)
    digest = hashlib.sha1(tag.encode()).hexdigest()[:12]
    slug = "".join(c if c.isalnum() else "-" for c in f"{case.key}-{peer.name}").strip("-")
    return cache_dir / f"{slug}-{digest}.json"


def sweep_peer(case: Case, peer: QualityPeer, scorer: Scorer, quick: bool,
               cache_dir: Path | None, log: Log) -> dict[str, Any]:
    """All settings of ``peer`` on ``case`` with their metrics (from the cache if present)."""
    path = _cache_file(cache_dir, case, peer, quick) if cache_dir is not None else None
    if path is not None and path.is_file():
        return dict(json.loads(path.read_text()))
    rows: list[dict[str, Any]] = []
    error: str | None = None
    t0 = time.perf_counter()
    for setting in peer.grid(case.shape, quick):
        t = time.perf_counter()
        try:
            if peer.isolated:
                X = run_isolated(peer.run, case.points, case.shape, setting)
            else:
                X = peer.run(case.points, case.shape, setting)
        except Exception as exc:  # a peer failing is a result
            error = f"{type(exc).__name__}: {exc}"
            if peer.isolated:
                break  # a crash repeats for every setting: do not fork again
            continue
        seconds = time.perf_counter() - t
        if X.shape != case.points.shape or not np.all(np.isfinite(X)):
            error = "non-finite or resized output"
            continue
        rows.append({"setting": _setting_str(setting), "seconds": seconds, **scorer.full(X)})
    out = {"peer": peer.name, "rows": rows, "error": error if not rows else None,
           "partial_error": error if rows else None, "seconds": time.perf_counter() - t0}
    log(f"    {peer.name}: {len(rows)} settings, {out['seconds']:.1f} s"
        + (f" ({error})" if error else ""))
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(out))
    return out


def best_of(rows: list[dict[str, Any]], metric: str) -> dict[str, Any] | None:
    """The row with the smallest ``metric``."""
    ok = [r for r in rows if r.get(metric) is not None and math.isfinite(r[metric])]
    return min(ok, key=lambda r: r[metric]) if ok else None


def lambda_oracle(evaluate: Callable[[float], dict[str, Any] | None], metric: str,
                  memo: dict[float, dict[str, Any] | None], lo: float = 1e-7, hi: float = 1e3,
                  refine: int = 8) -> dict[str, Any] | None:
    """Smallest ``metric`` over lambda: scan decades of ``[lo, hi]``, then golden section.

    ``evaluate(lam)`` returns the full metrics (with ``lambda`` and ``tau``) or ``None`` when
    the run fails; ``memo`` is shared between the metrics of one mode.
    """

    def f(log_lam: float) -> float:
        lam = float(10.0**log_lam)
        key = round(log_lam, 9)
        if key not in memo:
            memo[key] = evaluate(lam)
        r = memo[key]
        return math.inf if r is None else float(r[metric])

    grid = np.arange(math.log10(lo), math.log10(hi) + 1e-9, 1.0)
    vals = [f(x) for x in grid]
    i = int(np.argmin(vals))
    if not math.isfinite(vals[i]):
        return None
    a, b = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    g = (math.sqrt(5) - 1) / 2
    c, d = b - g * (b - a), a + g * (b - a)
    fc, fd = f(c), f(d)
    for _ in range(refine):
        if fc < fd:
            b, d, fd = d, c, fc
            c = b - g * (b - a)
            fc = f(c)
        else:
            a, c, fc = c, d, fd
            d = a + g * (b - a)
            fd = f(d)
    best = min((k for k in memo if memo[k] is not None), key=lambda k: memo[k][metric])  # type: ignore[index]
    return memo[best]
