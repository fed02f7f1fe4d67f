"""smooth(): the single entry point of the engine (being written; see issue 2)."""

from __future__ import annotations

from collections.abc import Callable

from service.core.geometry import Geometry
from service.core.params import SmoothingParams
from service.core.result import SmoothResult

ProgressCallback = Callable[[int, float, float], None]


def smooth(
    geometry: Geometry, params: SmoothingParams, progress: ProgressCallback | None = None
) -> SmoothResult:
    raise NotImplementedError
