"""Shared by the geographic formats (GPX, GeoJSON): degrees <-> the local metric frame, digits.

:class:`GeoFrame` turns longitude/latitude(/elevation) into metres (``geographic=True``: the
:class:`~service.io._shared.geo.LocalFrame` about the data's centre) or keeps them as planar numbers
(``geographic=False``, or a projected GeoJSON CRS), and back. Written values are rounded to the
decimals the input used (:func:`decimals`), so a track written back has the input's digits.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from service.io._shared.geo import LocalFrame
from service.io.errors import FormatError

__all__ = ["GeoFrame", "decimals", "near"]

_NUMBER = re.compile(r"-?\d+(?:\.(\d*))?(?:[eE][-+]?\d+)?")


def decimals(tokens: list[str], default: int = 9) -> int:
    """The largest number of decimals among number tokens (``default`` if any uses exponents)."""
    best = 0
    for tok in tokens:
        m = _NUMBER.fullmatch(tok.strip())
        if m is None or "e" in tok.lower():
            return default
        best = max(best, len(m.group(1) or ""))
    return best


def near(lon: float, before: float) -> float:
    """``lon`` on the side of the antimeridian ``before`` is (within [-180, 180])."""
    out = before + ((lon - before + 180.0) % 360.0 - 180.0)
    return out + 360.0 if out < -180.0 else out - 360.0 if out > 180.0 else out


def _check_degrees(lat: NDArray[np.float64], lon: NDArray[np.float64]) -> None:
    with np.errstate(invalid="ignore"):
        bad = ~(np.abs(lat) <= 90.0) | ~(np.abs(lon) <= 360.0)  # NaN fails both
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise FormatError(
            f"point {i} has latitude {lat[i]:g} and longitude {lon[i]:g}: geographic degrees"
            f" must lie in [-90, 90] and [-360, 360] ({int(bad.sum())} such points)"
        )


@dataclass(frozen=True)
class GeoFrame:
    """How longitude/latitude/elevation become the points smoothed, and back.

    Attributes
    ----------
    frame : LocalFrame or None
        ``None``: planar (x = longitude, y = latitude, z = elevation as given).
    has_ele : bool
        Whether every point has an elevation (it is then the third coordinate / the height).
    """

    frame: LocalFrame | None
    has_ele: bool

    @classmethod
    def of(
        cls,
        lon: NDArray[np.float64],
        lat: NDArray[np.float64],
        has_ele: bool,
        geographic: bool,
    ) -> GeoFrame:
        """The frame for these coordinates (``FormatError`` for a latitude outside
        [-90, 90] or a longitude outside [-360, 360] when they are geographic)."""
        if geographic:
            _check_degrees(lat, lon)
        return cls(LocalFrame.about(lat, lon) if geographic else None, has_ele)

    def points(
        self, lon: NDArray[np.float64], lat: NDArray[np.float64], ele: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """The points to smooth (metres in the local frame, or the planar values)."""
        if self.frame is None:
            return np.column_stack([lon, lat, ele] if self.has_ele else [lon, lat])
        h = ele if self.has_ele else np.zeros_like(lat)
        return self.frame.forward(lat, lon, h)

    def back(
        self, points: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64] | None]:
        """Longitude, latitude and elevation (``None`` without elevations) of points."""
        if self.frame is None:
            ele = points[:, 2] if self.has_ele else None
            return points[:, 0], points[:, 1], ele
        lat, lon, h = self.frame.inverse(points)
        return lon, lat, (h if self.has_ele else None)
