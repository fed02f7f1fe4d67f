"""The bookkeeping of one :func:`~service.core.pipeline.smooth` call: clock, progress events,
the resolved target and the notes that end up in the report's ``warnings``."""

from __future__ import annotations

import time
from typing import Any

from service.core.frame import Frame
from service.core.progress import ProgressCallback, ProgressEvent

__all__ = ["Run"]


class Run:
    """Clock, progress events and notes of one :func:`smooth` call (input-frame numbers)."""

    def __init__(self, progress: ProgressCallback | None, frame: Frame | None = None) -> None:
        self.t0 = time.perf_counter()
        self.progress = progress
        self.tau: float | None = None
        self.frame = frame
        self.notes: list[str] = []
        self.search_seconds = 0.0
        self.sigma: float | None = None  # core-quality: automatic tau, max-norm bound
        self.tau_how: str | None = None
        self.bound: dict[str, Any] | None = None
        self.data_weights: Any = None  # issue 21: service.core.noise.robust.DataWeights

    def emit(self, stage: str, **kw: Any) -> None:
        if self.progress is not None:
            elapsed = time.perf_counter() - self.t0
            self.progress(ProgressEvent(stage, tau=self.tau, elapsed=elapsed, **kw))

    def evaluated(self, lam: float, phi: float, iteration: int) -> None:
        """One ``search`` event per lambda tried (internal numbers converted)."""
        assert self.frame is not None
        f = self.frame
        self.emit("search", iteration=iteration, lam=f.lam_out(lam), phi=phi * f.phi_factor)
