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

__all__ = ["STAGES", "STEPS", "ProgressCallback", "ProgressEvent"]

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
    """

    stage: str
    tau: float | None = None
    iteration: int = 0
    lam: float | None = None
    phi: float | None = None
    elapsed: float = 0.0
    step: str | None = None

    @property
    def relative_error(self) -> float | None:
        """``|phi - tau| / tau`` when both are known."""
        if self.tau is None or self.phi is None or self.tau <= 0:
            return None
        return abs(self.phi - self.tau) / self.tau


ProgressCallback = Callable[[ProgressEvent], None]
