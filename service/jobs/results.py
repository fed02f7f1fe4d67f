"""A succeeded job's result as a document: the stored input read again, with the smoothed points.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from service.io import GeometryDocument

__all__ = ["load_result"]


def load_result(input_path: Path, points_path: Path, fmt: str, weld: bool) -> GeometryDocument:
    """Read the input (as the job did) and put the smoothed points ``result.npy`` into it."""
    from service.io import read_geometry

    points = np.load(points_path, allow_pickle=False)
    return read_geometry(input_path, fmt, weld=weld).with_points(points)
