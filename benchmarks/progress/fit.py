"""The progress model's phase costs from recorded runs, and its error on the others (issue 41).

``python -m benchmarks.progress.fit`` fits ``seconds = a + b * n`` per phase
(:data:`service.core.progress.PHASES`) by non-negative least squares on the calibration runs
(:data:`CALIBRATION`), prints the table for ``PHASE_COST`` and replays every recorded run
through :class:`service.core.progress.ProgressModel`: the time-left estimate over the truth,
from 10 % of the run on (the worst ratio either way), and whether the percent ever went back.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

RUNS = Path(__file__).with_name("runs")
#: Runs the costs are fitted on; the others are the test half.
CALIBRATION = ("las-30k", "las-300k")


def load(name: str) -> dict[str, Any]:
    return dict(json.loads((RUNS / f"{name}.json").read_text()))


def phase_entries(run: dict[str, Any]) -> list[tuple[str, float]]:
    """``(phase, elapsed)`` of each phase's first stage event, in order."""
    from service.core.progress import phase_of

    seen: dict[str, float] = {}
    for e in run["events"]:
        phase = phase_of(e["stage"], e.get("step"))
        if e["event"] == "stage" and phase is not None and phase not in seen:
            seen[phase] = float(e["elapsed_seconds"])
    return list(seen.items())


def durations(run: dict[str, Any]) -> dict[str, float]:
    entries = phase_entries(run)
    ends = [t for _, t in entries[1:]] + [float(run["wall_seconds"])]
    return {p: end - t for (p, t), end in zip(entries, ends, strict=True)}


def fit(names: tuple[str, ...] = CALIBRATION) -> dict[str, tuple[float, float]]:
    from service.core.progress import PHASES

    runs = [load(n) for n in names]
    out = {}
    for phase in PHASES:
        n = np.array([r["points"] for r in runs], dtype=float)
        d = np.array([durations(r).get(phase, 0.0) for r in runs])
        from scipy.optimize import nnls

        A = np.column_stack([np.ones_like(n), n])
        (a, b), _ = nnls(A, d)  # no negative cost: a phase never takes less than nothing
        out[phase] = (round(float(a), 4), float(f"{b:.4g}"))
    return out


def replay(run: dict[str, Any], step: float = 0.25) -> dict[str, Any]:
    """The model on a recorded run: worst time-left ratio from 10 % on, monotone percent,
    and the longest stretch the time left stayed the same (a frozen estimate)."""
    from service.core.progress import ProgressModel

    model = ProgressModel(run["points"])
    entries = phase_entries(run)
    total = float(run["wall_seconds"])
    worst, last_pct, back, frozen, same_since, last_eta = 1.0, 0.0, False, 0.0, 0.0, None
    marks: dict[str, float | None] = {}
    t = 0.0
    while t < total:
        for phase, at in entries:
            if at <= t:
                model.enter(phase, at)
        pct, eta = model.percent(t), model.eta(t)
        back |= pct < last_pct - 1e-9
        last_pct = pct
        if t >= 0.1 * total and eta is not None and total - t > 0.5:
            truth = total - t
            worst = max(worst, eta / truth, truth / max(eta, 1e-9))
        for q in (10, 25, 50, 75):
            if f"{q}%" not in marks and t >= q / 100 * total:
                marks[f"{q}%"] = None if eta is None else round(eta / (total - t), 2)
        if eta is not None and last_eta is not None and abs(eta - last_eta) < 1e-9:
            frozen = max(frozen, t - same_since)
        else:
            same_since = t
        last_eta = eta
        t += step
    return {"name": run["name"], "points": run["points"], "wall_seconds": total,
            "cpu_seconds": run.get("cpu_seconds"), "load": run.get("load"),
            "calibration": run["name"] in CALIBRATION,
            "worst_eta_ratio": round(worst, 3), "eta_over_truth_at": marks,
            "percent_went_back": back,
            "longest_frozen_seconds": round(frozen, 2)}  # fmt: skip


def main() -> None:
    print("PHASE_COST =", json.dumps(fit(), indent=1))
    for path in sorted(RUNS.glob("*.json")):
        row = replay(json.loads(path.read_text()))
        half = "calibration" if row["name"] in CALIBRATION else "test"
        print(half, row)


if __name__ == "__main__":
    main()
