"""WGS84 geographic coordinates <-> a local metric frame (east, north, up), exactly invertible.

GPX tracks and GeoJSON lines are in degrees; smoothing them needs metres, so that ``rms=3`` means
3 m. :class:`LocalFrame` is the local tangent plane about the data's centre: geodetic
(latitude, longitude, ellipsoidal height) -> ECEF (WGS84) -> a rotation and translation to
east/north/up about the centre. It is a rigid transform of ECEF, so distances are true (chordal)
distances everywhere, also for data spanning a continent, and ``up`` is the height above the
tangent plane (close to the elevation near the centre). Data without elevation is placed on the
ellipsoid (height 0) and written back without one. The inverse uses Heikkinen's closed form
(ECEF -> geodetic), exact to far below a millimetre.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["LocalFrame", "ecef_to_geodetic", "geodetic_to_ecef"]

A = 6378137.0
F = 1 / 298.257223563
E2 = F * (2 - F)
B = A * (1 - F)


def geodetic_to_ecef(
    lat: NDArray[np.float64], lon: NDArray[np.float64], h: NDArray[np.float64]
) -> NDArray[np.float64]:
    """ECEF metres of latitude/longitude in degrees and height in metres."""
    phi, lam = np.radians(lat), np.radians(lon)
    n = A / np.sqrt(1 - E2 * np.sin(phi) ** 2)
    return np.column_stack(
        [
            (n + h) * np.cos(phi) * np.cos(lam),
            (n + h) * np.cos(phi) * np.sin(lam),
            (n * (1 - E2) + h) * np.sin(phi),
        ]
    )


def ecef_to_geodetic(
    xyz: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Latitude, longitude (degrees) and height (metres) of ECEF points (Heikkinen, 1982)."""
    x, y, z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    ep2 = (A * A - B * B) / (B * B)
    p = np.hypot(x, y)
    f54 = 54 * B * B * z * z
    g = p * p + (1 - E2) * z * z - E2 * (A * A - B * B)
    c = E2 * E2 * f54 * p * p / g**3
    s = np.cbrt(1 + c + np.sqrt(c * c + 2 * c))
    k = s + 1 + 1 / s
    pp = f54 / (3 * k * k * g * g)
    q = np.sqrt(1 + 2 * E2 * E2 * pp)
    r0 = -(pp * E2 * p) / (1 + q) + np.sqrt(
        np.maximum(
            0.5 * A * A * (1 + 1 / q) - pp * (1 - E2) * z * z / (q * (1 + q)) - 0.5 * pp * p * p,
            0.0,
        )
    )
    u = np.hypot(p - E2 * r0, z)
    v = np.sqrt((p - E2 * r0) ** 2 + (1 - E2) * z * z)
    z0 = B * B * z / (A * v)
    h = u * (1 - B * B / (A * v))
    lat = np.degrees(np.arctan2(z + ep2 * z0, p))
    lon = np.degrees(np.arctan2(y, x))
    return lat, lon, h


@dataclass(frozen=True)
class LocalFrame:
    """East/north/up about a centre (see the module docstring)."""

    lat0: float
    lon0: float
    origin: tuple[float, float, float]

    @classmethod
    def about(cls, lat: NDArray[np.float64], lon: NDArray[np.float64]) -> LocalFrame:
        """The frame at the centre of the points (the mean of their ECEF positions)."""
        mean = geodetic_to_ecef(lat, lon, np.zeros_like(lat)).mean(axis=0)
        if not np.any(mean):
            mean = np.array([A, 0.0, 0.0])
        lat0, lon0, _ = ecef_to_geodetic(mean[None, :])
        centre = geodetic_to_ecef(lat0, lon0, np.zeros(1))[0]
        return cls(
            float(lat0[0]), float(lon0[0]), (float(centre[0]), float(centre[1]), float(centre[2]))
        )

    def _rotation(self) -> NDArray[np.float64]:
        phi, lam = np.radians(self.lat0), np.radians(self.lon0)
        sp, cp, sl, cl = np.sin(phi), np.cos(phi), np.sin(lam), np.cos(lam)
        return np.array([[-sl, cl, 0.0], [-sp * cl, -sp * sl, cp], [cp * cl, cp * sl, sp]])

    def forward(
        self, lat: NDArray[np.float64], lon: NDArray[np.float64], h: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """East, north, up (metres) of geodetic points (a non-finite or overflowing height
        gives non-finite coordinates, refused with the point named by the Geometry check,
        without a NumPy warning on stderr)."""
        with np.errstate(invalid="ignore", over="ignore"):
            return (geodetic_to_ecef(lat, lon, h) - np.asarray(self.origin)) @ self._rotation().T

    def inverse(
        self, enu: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Latitude, longitude (degrees) and height (metres) of east/north/up points."""
        return ecef_to_geodetic(enu @ self._rotation() + np.asarray(self.origin))
