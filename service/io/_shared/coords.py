"""Coordinates for the formats that store exactly three of them (PLY and OBJ)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from service.io.errors import FormatError

__all__ = ["as_xyz"]


def as_xyz(points: NDArray[np.float64], fmt: str) -> NDArray[np.float64]:
    """Points as ``(n, 3)``: 3D unchanged, 2D with ``z = 0``.

    Raises
    ------
    FormatError
        For 1 or more than 3 coordinates per point, which PLY and OBJ cannot represent.
    """
    s = points.shape[1]
    if s == 3:
        return points
    if s == 2:
        return np.column_stack([points, np.zeros(len(points))])
    raise FormatError(
        f"{fmt.upper()} stores 2D or 3D points; this geometry has {s} coordinates per point:"
        " write it as JSON or XYZ instead",
        fmt=fmt,
    )
