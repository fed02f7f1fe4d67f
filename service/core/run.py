"""The bookkeeping of one :func:`~service.core.pipeline.smooth_one` call: the clock, the
progress callback and the solve stage's warnings (typed records, :mod:`.warnings`, in run order).

Everything a stage decides travels in the record it returns (:class:`~service.core.plan.Plan`,
:class:`~service.core.problem.Problem`, :class:`~service.core.search.target.Target`, ...), not
here: the set-up's warnings are the problem's, the outliers' the finish stage's, the checks' the
report's. ``notes`` is where the lambda search (``service/core/search``) still writes strings;
they become :data:`~service.core.warnings.LEGACY` warnings in their run order.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from service.core.frame import Frame
from service.core.progress import ProgressCallback, ProgressEvent
from service.core.warnings import LEGACY, EngineWarning

__all__ = ["Run"]


class Run:
    """Clock, progress events and the solve stage's warnings of one run (input-frame numbers)."""

    def __init__(self, progress: ProgressCallback | None) -> None:
        self.t0 = time.perf_counter()
        self.progress = progress
        self.notes: list[str] = []  # strings of the lambda search (untyped, issue 38)
        self._warnings: list[EngineWarning] = []

    def warn(self, *warnings: EngineWarning) -> None:
        """Warnings of the solve stage, after any note the search wrote before them."""
        self._warnings.extend([*self._legacy(), *warnings])

    @property
    def warnings(self) -> tuple[EngineWarning, ...]:
        """Every warning of the solve stage so far, in run order."""
        self._warnings.extend(self._legacy())
        return tuple(self._warnings)

    def _legacy(self) -> list[EngineWarning]:
        said = [EngineWarning(LEGACY, note) for note in self.notes]
        self.notes.clear()
        return said

    def emit(self, stage: str, tau: float | None = None, **kw: Any) -> None:
        """One progress event; ``tau`` is the resolved target from the ``analysis`` stage on."""
        if self.progress is not None:
            elapsed = time.perf_counter() - self.t0
            self.progress(ProgressEvent(stage, tau=tau, elapsed=elapsed, **kw))

    def listener(self, frame: Frame, tau: float | None) -> Callable[[float, float, int], None]:
        """The callback of :class:`~service.core.system.deviation.Deviation`: one ``search``
        event per lambda tried, internal numbers converted to the input's."""

        def evaluated(lam: float, phi: float, iteration: int) -> None:
            self.emit(
                "search", tau=tau, iteration=iteration, lam=frame.lam_out(lam),
                phi=frame.phi_out(phi),
            )  # fmt: skip

        return evaluated

    def step(self, name: str) -> None:
        """A ``neighborhoods`` event naming the part under way
        (:data:`~service.core.progress.STEPS`)."""
        self.emit("neighborhoods", step=name)
