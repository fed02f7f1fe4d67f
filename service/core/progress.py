"""Progress events of :func:`service.core.smooth` (the callback's one argument).

The engine resolves the target ``tau`` (given, or ``sum_i omega_i^2 rms^2`` over the points that
can move, report eq. 3) once, and every event from the ``analysis`` stage on carries it, so the
CLI, the job queue and the HTTP events show the same target from the start. Outer layers add
their own stages (``queued``, ``reading``, ``writing``) with the same event type. Inside
``neighborhoods`` an event's ``step`` names the part under way (:data:`STEPS`: the data weights,
then the noise estimate and tau), for displays that show them (the CLI's stage lines).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

__all__ = [
    "PHASES",
    "STAGES",
    "STEPS",
    "ProgressCallback",
    "ProgressEvent",
    "ProgressModel",
    "phase_of",
    "phase_shares",
]

#: Stages in the order a run goes through them (the engine's are ``neighborhoods`` .. ``done``).
STAGES: tuple[str, ...] = (
    "queued",
    "reading",
    "neighborhoods",
    "laplacian",
    "analysis",
    "search",
    "postprocess",
    "writing",
    "done",
)

#: Parts of the ``neighborhoods`` stage an event's ``step`` names, in run order.
STEPS: tuple[str, ...] = ("weights", "noise")


@dataclass(frozen=True)
class ProgressEvent:
    """One progress report.

    Attributes
    ----------
    stage : str
        One of :data:`STAGES`.
    tau : float or None
        The resolved target ``tau`` (``None`` while unknown, or when ``lam`` was given).
    iteration : int
        lambda values tried so far (0 before the first).
    lam, phi : float or None
        The lambda just tried and its deviation ``phi(lam)`` (eq. 15), for ``search`` events.
    elapsed : float
        Seconds since the run started.
    step : str or None
        One of :data:`STEPS` (inside ``neighborhoods``), else ``None``.
    fraction : float or None
        Share of the stage's work done (tiled runs: points of the tiles done).
    tiles_done, tiles_total : int or None
        Tiles finished and in all (tiled runs).
    points_per_second : float or None
        Points smoothed per second so far (tiled runs).
    seconds_left : float or None
        The run's own estimate of the time left (tiled runs: measured seconds per point).
    """

    stage: str
    tau: float | None = None
    iteration: int = 0
    lam: float | None = None
    phi: float | None = None
    elapsed: float = 0.0
    step: str | None = None
    fraction: float | None = None
    tiles_done: int | None = None
    tiles_total: int | None = None
    points_per_second: float | None = None
    seconds_left: float | None = None

    @property
    def relative_error(self) -> float | None:
        """``|phi - tau| / tau`` when both are known."""
        if self.tau is None or self.phi is None or self.tau <= 0:
            return None
        return abs(self.phi - self.tau) / self.tau


ProgressCallback = Callable[[ProgressEvent], None]


# --------------------------------------------------------------------------- the cost model

#: The parts of a run the progress model times, in run order: the stages, ``neighborhoods``
#: split at its steps (issue 41). ``laplacian`` is built inside ``neighborhoods``.
PHASES: tuple[str, ...] = (
    "reading",
    "neighborhoods",
    "neighborhoods:weights",
    "neighborhoods:noise",
    "analysis",
    "search",
    "postprocess",
    "writing",
)

#: Seconds of each phase as ``a + b * n`` (n points), measured on the calibration runs of
#: ``benchmarks/progress`` (``python -m benchmarks.progress.fit``): only the ratios matter (a
#: busy or fast machine scales every phase alike).
PHASE_COST: dict[str, tuple[float, float]] = {
    "reading": (1.4285, 0.0),
    "neighborhoods": (0.5747, 3.841e-05),
    "neighborhoods:weights": (2.3006, 1.815e-05),
    "neighborhoods:noise": (0.004, 0.0),
    "analysis": (0.0, 0.0001445),
    "search": (3.9795, 0.0),
    "postprocess": (0.0, 2.772e-06),
    "writing": (0.075, 6.333e-07),
}


def phase_of(stage: str, step: str | None = None) -> str | None:
    """The phase of an event (``None``: a stage the model does not time, ``queued``, ``done``)."""
    if stage == "laplacian":
        stage = "neighborhoods"
    name = f"{stage}:{step}" if step else stage
    return name if name in PHASES else None


def phase_shares(n: int) -> dict[str, float]:
    """Each phase's share of a run of ``n`` points (summing to 1)."""
    cost = {p: max(a + b * n, 0.0) for p, (a, b) in PHASE_COST.items()}
    total = sum(cost.values())
    if total <= 0:
        return {p: 1.0 / len(PHASES) for p in PHASES}
    return {p: cost.get(p, 0.0) / total for p in PHASES}


class ProgressModel:
    """Percent done and time left of one run, from the phases' measured shares (issue 41).

    At the start of a phase the run's total time is estimated as the time so far over the
    shares of the phases done; inside a phase the percent moves with the time spent against
    that phase's expected share (capped at its end), and a phase that overruns stretches the
    total (as if it were about to end): the percent never goes back, the time left moves
    every second and is never frozen. No estimate before the first phase ends.

    Parameters
    ----------
    n : int
        Points of the input (the shares depend on it).
    """

    def __init__(self, n: int) -> None:
        self.shares = phase_shares(max(int(n), 1))
        self.phase: str | None = None
        self.start = 0.0
        self.before = 0.0  # share of the phases done

    def enter(self, phase: str, elapsed: float) -> None:
        """Phase ``phase`` starts ``elapsed`` seconds into the run (later phases only)."""
        if phase not in self.shares or phase == self.phase:
            return
        if self.phase is not None and PHASES.index(phase) < PHASES.index(self.phase):
            return  # a tiled run's later tile: the phase is under way already
        order = PHASES[: PHASES.index(phase)]
        self.before = sum(self.shares[p] for p in order)
        self.phase, self.start = phase, float(elapsed)

    def total(self, elapsed: float) -> float | None:
        """The estimated total seconds of the run (``None`` before the first phase ends)."""
        if self.phase is None or self.before < 1e-3 or self.start <= 0:
            return None
        share = self.shares[self.phase]
        total = self.start / self.before
        if elapsed > self.start + share * total:  # the phase overruns: as if it ended now
            total = elapsed / min(self.before + share, 1.0)
        return max(total, elapsed)

    def percent(self, elapsed: float) -> float:
        """Percent of the run done at ``elapsed`` seconds (0-100, never going back)."""
        total = self.total(elapsed)
        if total is None:
            return 0.0
        end = self.before + (self.shares[self.phase] if self.phase else 0.0)
        return 100.0 * min(max(elapsed / total, self.before), end)

    def eta(self, elapsed: float) -> float | None:
        """Seconds left at ``elapsed`` (``None`` before the first phase ends)."""
        total = self.total(elapsed)
        return None if total is None else max(total - elapsed, 0.0)
