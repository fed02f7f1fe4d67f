"""The progress dict of a job, from the engine's :class:`~service.core.progress.ProgressEvent`.

``{stage, iteration, lambda, phi, tau, relative_error, percent, eta_seconds, elapsed_seconds}``
is stored with the job (the same dict for every backend) and shown by ``GET /v1/jobs/{id}`` and
the events stream from the first stage on (``queued``, ``reading``, ``neighborhoods``, ...).

``percent`` is a stage-weighted estimate: each stage owns a slice of 0-100 (the slices follow the
share of the run time the stages took on the benchmark shapes: the lambda search dominates);
inside ``search`` the slice is filled by how far the relative error ``|phi - tau| / tau`` has come
down, on a log scale, from its first value to the tolerance (the search converges roughly
geometrically). An event's own ``fraction`` (0-1 of its stage), when the engine gives one, wins.
``eta_seconds`` extrapolates the elapsed time linearly from ``percent`` (``None`` below 5 %).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from service.core.params import TOLERANCE

if TYPE_CHECKING:
    from service.core.progress import ProgressEvent

__all__ = ["STAGE_SLICES", "ProgressTracker", "final_progress", "queued_progress"]

#: Stage -> (start, end) percent.
STAGE_SLICES: dict[str, tuple[float, float]] = {
    "queued": (0.0, 0.0),
    "reading": (0.0, 5.0),
    "neighborhoods": (5.0, 20.0),
    "laplacian": (20.0, 30.0),
    "analysis": (30.0, 40.0),
    "search": (40.0, 90.0),
    "postprocess": (90.0, 95.0),
    "writing": (95.0, 100.0),
    "done": (100.0, 100.0),
}
_MIN_PERCENT_FOR_ETA = 5.0


def queued_progress(stage: str = "queued") -> dict[str, Any]:
    """The progress dict before the engine reported anything (``queued`` or ``reading``)."""
    return {
        "stage": stage,
        "iteration": 0,
        "lambda": None,
        "phi": None,
        "tau": None,
        "relative_error": None,
        "percent": STAGE_SLICES[stage][0],
        "eta_seconds": None,
        "elapsed_seconds": 0.0,
    }


def final_progress(report: dict[str, Any], elapsed: float) -> dict[str, Any]:
    """The progress dict of a succeeded run, from its report."""

    def num(key: str) -> Any:
        value = report.get(key)
        return value if isinstance(value, int | float) and not isinstance(value, bool) else None

    return {
        "stage": "done",
        "iteration": num("iterations") or 0,
        "lambda": num("lambda"),
        "phi": num("phi"),
        "tau": num("tau"),
        "relative_error": num("relative_error"),
        "percent": 100.0,
        "eta_seconds": 0.0,
        "elapsed_seconds": round(elapsed, 3),
    }


@dataclass
class ProgressTracker:
    """Turns progress events of one run into progress dicts.

    Parameters
    ----------
    tolerance : float
        Relative tolerance of the tau search (the end of the ``search`` slice).
    """

    tolerance: float = TOLERANCE
    _first_error: float | None = field(default=None, repr=False)
    _last: dict[str, Any] = field(default_factory=dict, repr=False)

    def update(self, event: ProgressEvent) -> dict[str, Any]:
        """The progress dict for ``event``.

        The search's latest ``iteration``, ``lambda``, ``phi``, ``tau`` and relative error carry
        over to the later stages (``postprocess``, ``writing``), whose events do not repeat
        them: the iteration count never goes back within a run.
        """
        rel = event.relative_error
        percent = self._percent(event, rel)
        elapsed = float(event.elapsed)
        eta = None
        if percent >= 100.0:
            eta = 0.0
        elif (left := getattr(event, "seconds_left", None)) is not None:  # a tiled run's own
            eta = round(float(left), 3)
        elif percent >= _MIN_PERCENT_FOR_ETA and elapsed > 0:
            eta = round(elapsed * (100.0 - percent) / percent, 3)
        last = self._last
        found = {"lambda": _finite(event.lam), "phi": _finite(event.phi),
                 "tau": _finite(event.tau), "relative_error": _finite(rel)}  # fmt: skip
        values = {k: last.get(k) if v is None else v for k, v in found.items()}
        self._last = {**values, "iteration": max(int(event.iteration), last.get("iteration", 0))}
        return {
            "stage": event.stage,
            "iteration": self._last["iteration"],
            **values,
            "percent": round(percent, 2),
            "eta_seconds": eta,
            "elapsed_seconds": round(elapsed, 3),
            **_tiles(event),
        }

    def _percent(self, event: ProgressEvent, rel: float | None) -> float:
        start, end = STAGE_SLICES.get(event.stage, (0.0, 0.0))
        fraction = getattr(event, "fraction", None)  # an optional field of the engine's events
        if fraction is None and event.stage == "search":
            fraction = self._search_fraction(rel)
        if fraction is None or not math.isfinite(fraction):
            fraction = 0.0
        return start + (end - start) * min(1.0, max(0.0, float(fraction)))

    def _search_fraction(self, rel: float | None) -> float | None:
        if rel is None or not math.isfinite(rel) or rel <= 0:
            return None if rel is None else 1.0
        if self._first_error is None:
            self._first_error = rel
        first, tol = self._first_error, max(self.tolerance, 1e-15)
        if first <= tol:
            return 1.0
        return math.log(first / max(rel, tol)) / math.log(first / tol)


def _tiles(event: ProgressEvent) -> dict[str, Any]:
    """A tiled run's counter: tiles done and in all, points per second (issue 43)."""
    total = getattr(event, "tiles_total", None)
    if not total:
        return {}
    return {"tiles_done": event.tiles_done, "tiles_total": total,
            "points_per_second": _finite(event.points_per_second)}


def _finite(value: float | None) -> float | None:
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None


class TileCounter:
    """Tiles finished in the current round, for the progress dict's ``tiles`` member."""

    def __init__(self) -> None:
        self.done = 0
        self.total = 0
        self.rounds = 0
        self.retried = 0

    def as_dict(self) -> dict[str, int]:
        return {"done": self.done, "total": self.total, "round": self.rounds,
                "retried": self.retried}  # fmt: skip
