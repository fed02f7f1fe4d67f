"""Unchanged is byte-identical (issue 32): how :mod:`service.workflows.smooth_file` tells that
the engine smoothed nothing, and what it then writes.

Whatever the reason (no noise found, every point fixed, nothing coupled, no valid budget), a
run smoothed nothing when its points are the input's bit for bit (:func:`returned_unchanged`).
Its output is then the input's bytes (:data:`COPIED`) in the input's format without writer
options, else a straight conversion (:data:`CONVERTED`); the result's ``unchanged`` member
(:func:`marked`) puts that in every report.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from service.core.result import SmoothResult

__all__ = ["CONVERTED", "COPIED", "WORDS", "Original", "marked", "original_bytes",
           "returned_unchanged"]  # fmt: skip

#: The input's bytes, or the file holding them (kept to copy an unchanged input).
Original = bytes | Path
#: ``unchanged`` of a run whose output is the input's bytes, copied.
COPIED = "copied"
#: ``unchanged`` of a run whose unchanged points were converted (another format or options).
CONVERTED = "converted"
#: The summary's words for each.
WORDS = {COPIED: "returned unchanged: input bytes copied", CONVERTED: "converted unchanged"}


def returned_unchanged(result: SmoothResult, points: Any) -> bool:
    """Whether ``result`` holds ``points`` bit for bit (the engine smoothed nothing)."""
    import numpy as np

    if result.max_displacement != 0.0:
        return False
    ours = np.asarray(points)
    return bool(result.points.shape == ours.shape and np.array_equal(result.points, ours))


def marked(result: SmoothResult, how: str) -> SmoothResult:
    """``result`` with its ``unchanged`` member set (so its report says it)."""
    return dataclasses.replace(result, unchanged=how)


def original_bytes(original: Original | None) -> bytes | None:
    """The input's bytes (``None``: not at hand, or the file cannot be read again)."""
    if original is None or isinstance(original, bytes):
        return original
    try:
        return Path(original).read_bytes()
    except OSError:
        return None
