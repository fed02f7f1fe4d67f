"""Issue 31's CAD shapes: flat faces, sharp convex and concave creases, corners.

* ``cube-6K``: the 2 x 2 x 2 box midpoint-subdivided 5 times (6146 vertices; the issue's
  "subdivided cube"; ``box`` of :mod:`~benchmarks.quality.shapes` is the same cube subdivided 4
  times, 1538 vertices), exact distance to the cube;
* ``bracket``: an L-shaped bracket (a base plate with an upright flange), and ``stepblock``: a
  block with three steps. Both are unions of unit voxels whose boundary squares are each split
  into a regular ``m x m`` grid of right triangles (same diagonal everywhere), scaled to a
  largest extent of 2 and turned by a fixed generic rotation (no face is parallel to a
  coordinate plane: rounding coordinates to a grid then moves every face's points off it).

The clean triangle mesh of a bracket or a step block *is* the true surface (its faces are
flat), so the distance to it (:class:`benchmarks.metrics.SurfaceDistance`) is exact.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from benchmarks import metrics
from benchmarks.quality.shapes import Shape, _crease_vertices, frame_from_normal, vertex_normals
from benchmarks.shapes import box_mesh, mean_edge_length

__all__ = ["bracket", "cube", "stepblock", "voxel_surface"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

#: A fixed generic rotation (Euler angles z-y-x, degrees) applied to the voxel parts.
ANGLES = (27.0, 38.0, 14.0)


def cube(subdivisions: int = 5) -> Shape:
    """The box of :func:`benchmarks.quality.shapes.box`, subdivided ``subdivisions`` times."""
    c = box_mesh(subdivisions=subdivisions, sigma=0.0)
    P, F = c.points, c.faces
    assert F is not None
    q = np.abs(P)
    nrm = np.where(q >= q.max(axis=1, keepdims=True) - 1e-12, np.sign(P), 0.0)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    h = mean_edge_length(P, F)
    sharp = np.sort(q, axis=1)[:, 1] > 1.0 - 2.5 * h
    return Shape(f"cube {len(P) / 1000:.0f}K", P, F, None, frame_from_normal(nrm), 1,
                 lambda X: metrics.box_distance(X, 1.0), h, closed=True, sharp=sharp,
                 source=f"box 2x2x2 subdivided {subdivisions}x (sharp edges and corners)")


def voxel_surface(occupied: BoolArray, m: int) -> tuple[FloatArray, IntArray]:
    """The boundary of a union of unit voxels as a welded, outward-oriented triangle mesh whose
    every boundary square is an ``m x m`` grid (two triangles per cell, one diagonal)."""
    lattice: list[NDArray[np.int64]] = []
    tris: list[NDArray[np.int64]] = []
    g = np.arange(m + 1)
    X, Y = np.meshgrid(g, g, indexing="ij")
    cell = (X[:-1, :-1] * (m + 1) + Y[:-1, :-1]).ravel()
    t_up = np.stack([cell, cell + m + 1, cell + m + 2], 1)  # (x, y), (x+1, y), (x+1, y+1)
    t_lo = np.stack([cell, cell + m + 2, cell + 1], 1)
    local = np.vstack([t_up, t_lo])
    shape = occupied.shape
    count = 0
    for idx in np.argwhere(occupied):
        for a in range(3):
            for s in (-1, 1):
                nb = idx.copy()
                nb[a] += s
                if 0 <= nb[a] < shape[a] and occupied[tuple(nb)]:
                    continue
                b, c = (a + 1) % 3, (a + 2) % 3
                origin = idx * m
                origin[a] += m if s > 0 else 0
                pts = np.repeat(origin[None], (m + 1) ** 2, axis=0)
                pts[:, b] += X.ravel()
                pts[:, c] += Y.ravel()
                lattice.append(pts)
                tris.append((local if s > 0 else local[:, ::-1]) + count)
                count += len(pts)
    L = np.vstack(lattice)
    uniq, inverse = np.unique(L, axis=0, return_inverse=True)
    F = inverse.ravel()[np.vstack(tris)]
    return uniq.astype(np.float64) / m, F.astype(np.int64)


def _rotation(angles: tuple[float, float, float]) -> FloatArray:
    z, y, x = np.radians(angles)
    Rz = np.array([[np.cos(z), -np.sin(z), 0], [np.sin(z), np.cos(z), 0], [0, 0, 1]])
    Ry = np.array([[np.cos(y), 0, np.sin(y)], [0, 1, 0], [-np.sin(y), 0, np.cos(y)]])
    Rx = np.array([[1, 0, 0], [0, np.cos(x), -np.sin(x)], [0, np.sin(x), np.cos(x)]])
    return Rz @ Ry @ Rx


def _part(name: str, occupied: BoolArray, m: int, source: str) -> Shape:
    P, F = voxel_surface(occupied, m)
    P = (P - 0.5 * (P.min(axis=0) + P.max(axis=0))) * (2.0 / np.ptp(P, axis=0).max())
    P = P @ _rotation(ANGLES).T
    h = mean_edge_length(P, F)
    return Shape(name, P, F, None, frame_from_normal(vertex_normals(P, F)), 1,
                 metrics.SurfaceDistance(P, F), h, closed=True,
                 sharp=_crease_vertices(P, F, h), source=source)


def bracket(m: int = 6) -> Shape:
    """L-shaped bracket: a 5 x 3 x 1 base plate and a 1 x 3 x 3 flange on one end."""
    occ = np.zeros((5, 3, 4), dtype=bool)
    occ[:, :, 0] = True
    occ[0, :, 1:] = True
    return _part("L bracket", occ, m,
                 f"L bracket (base 5x3x1 + flange 1x3x3 voxels), {m}x{m} grid per square, rotated")


def stepblock(m: int = 6) -> Shape:
    """A block of three steps (4 x 3 cells, heights 3, 2, 1, 1)."""
    occ = np.zeros((4, 3, 3), dtype=bool)
    for i, height in enumerate((3, 2, 1, 1)):
        occ[i, :, :height] = True
    return _part("step block", occ, m,
                 f"step block (3 steps, 4x3x3 voxels), {m}x{m} grid per square, rotated")
