"""Synthetic terrain for the tiles benchmark: fractal heights (48 random-phase waves with
wavelengths from the side down to side/64, amplitude ~ wavelength^0.8) sampled by scattered
points (aerial LiDAR) or a jittered grid triangulated (a DEM mesh), Gaussian height noise."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import Delaunay


def heights(xy: NDArray[np.float64], side: float, seed: int = 0) -> NDArray[np.float64]:
    rng = np.random.default_rng(seed)
    z = np.zeros(xy.shape[0])
    for _ in range(48):
        wavelength = side * 2.0 ** (-rng.uniform(0, 6))
        angle = rng.uniform(0, 2 * np.pi)
        k = 2 * np.pi / wavelength * np.array([np.cos(angle), np.sin(angle)])
        z += 0.05 * wavelength**0.8 * np.sin(xy @ k + rng.uniform(0, 2 * np.pi))
    return z


def cloud(n: int, spacing: float = 0.5, sigma: float = 0.05, seed: int = 0) -> NDArray[np.float64]:
    """``n`` points, about ``spacing`` apart, noise ``sigma`` (metres)."""
    side = spacing * np.sqrt(n)
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, side, (n, 2))
    return np.c_[xy, heights(xy, side, seed) + sigma * rng.standard_normal(n)]


def mesh(
    m: int, spacing: float = 0.5, sigma: float = 0.05, seed: int = 0
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """An ``m x m`` jittered grid, Delaunay-triangulated without the hull's slivers."""
    side = spacing * m
    rng = np.random.default_rng(seed)
    g = np.linspace(0, side, m)
    X, Y = np.meshgrid(g, g)
    xy = np.c_[X.ravel(), Y.ravel()] + rng.uniform(-0.2, 0.2, (m * m, 2)) * spacing
    faces = Delaunay(xy).simplices.astype(np.int64)
    longest = np.max([np.linalg.norm(xy[faces[:, i]] - xy[faces[:, (i + 1) % 3]], axis=1)
                      for i in range(3)], axis=0)  # fmt: skip
    faces = faces[longest < 3 * spacing]
    z = heights(xy, side, seed) + sigma * rng.standard_normal(m * m)
    return np.c_[xy, z], faces
