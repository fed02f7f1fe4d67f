"""Issue 40's shapes: thin parts, CAD triangles, steps, boundaries, duplicates (exact truth).

Three builders give every shape an exact distance to its true surface:

* :func:`revolve`: a surface of revolution of a polyline profile ``(r, z)`` (poles where the
  profile meets the axis: fans of valence ``ntheta``); the distance of a point to it is the 2-D
  distance of ``(sqrt(x^2 + y^2), z)`` to the profile (closed cylinders with 20:1 or 4:1 side
  triangles, thin-walled cups, coarse ellipsoids);
* :func:`extrude`: a profile ``(x, z)`` swept along ``y`` (a hairpin-folded strip, 90° stairs):
  the 2-D distance to the profile, plus the overshoot beyond the strip's ends;
* :func:`holed_plate`: a planar plate with circular holes (Delaunay of boundary samples and a
  jittered interior grid): the distance to its plane; its boundary vertices are scored apart.

The thin CAD plate is :func:`benchmarks.quality.cad.voxel_surface` of one layer of voxels,
flattened to the plate's thickness (the clean mesh is the true surface: its faces are flat).
Every generator is deterministic.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import Delaunay, cKDTree

from benchmarks import metrics
from benchmarks.quality.cad import _rotation, voxel_surface
from benchmarks.quality.shapes import Shape, frame_from_normal, sphere_cloud, vertex_normals
from benchmarks.shapes import mean_edge_length

__all__ = ["boundary_vertices", "cup", "cylinder", "duplicated_cloud", "ellipsoid", "fold",
           "holed_plate", "plate", "profile_distance", "revolve", "stairs"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
ANGLES = (31.0, 23.0, 17.0)


def profile_distance(Q: FloatArray, V: FloatArray) -> FloatArray:
    """Distance of 2-D points ``Q`` to the polyline through ``V`` (exact, chunked)."""
    A, B = V[:-1], V[1:]
    D = B - A
    L2 = np.maximum(np.sum(D**2, axis=1), 1e-300)
    out = np.empty(len(Q))
    for s in range(0, len(Q), 2000):
        q = Q[s:s + 2000, None, :]
        t = np.clip(np.sum((q - A) * D, axis=2) / L2, 0.0, 1.0)
        out[s:s + 2000] = np.sqrt(np.min(np.sum((q - A - t[..., None] * D) ** 2, axis=2), axis=1))
    return out


def _subdivide(corners: list[tuple[float, float]], counts: list[int]) -> FloatArray:
    pts = [np.asarray(corners[0], dtype=np.float64)[None]]
    for a, b, m in zip(corners[:-1], corners[1:], counts, strict=True):
        t = np.linspace(0.0, 1.0, m + 1)[1:, None]
        pts.append((1 - t) * np.asarray(a) + t * np.asarray(b))
    return np.vstack(pts)


def _shape(name: str, P: FloatArray, F: IntArray, dist: Callable[[FloatArray], FloatArray],
           source: str, closed: bool, **extra: object) -> Shape:
    return Shape(name, P, F, None, frame_from_normal(vertex_normals(P, F)), 1, dist,
                 mean_edge_length(P, F), closed=closed, source=source, extra=dict(extra))


def revolve(profile: FloatArray, ntheta: int) -> tuple[FloatArray, IntArray]:
    """Vertices and outward faces of the surface of revolution of ``profile`` ((r, z) rows;
    rows with ``r = 0`` are poles)."""
    th = 2 * np.pi * np.arange(ntheta) / ntheta
    rings: list[IntArray] = []
    pts: list[FloatArray] = []
    count = 0
    for r, z in profile:
        if r <= 0:
            pts.append(np.array([[0.0, 0.0, z]]))
            rings.append(np.full(ntheta, count))
            count += 1
        else:
            pts.append(np.stack([r * np.cos(th), r * np.sin(th), np.full(ntheta, z)], 1))
            rings.append(count + np.arange(ntheta))
            count += ntheta
    tris: list[IntArray] = []
    for a, b in itertools.pairwise(rings):
        a1, b1 = np.roll(a, -1), np.roll(b, -1)
        for t in (np.stack([a, a1, b1], 1), np.stack([a, b1, b], 1)):
            tris.append(t[(t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 0] != t[:, 2])])
    P, F = np.vstack(pts), np.vstack(tris).astype(np.int64)
    e1, e2 = P[F[:, 1]] - P[F[:, 0]], P[F[:, 2]] - P[F[:, 0]]
    if np.sum(P[F[:, 0]] * np.cross(e1, e2)) < 0:
        F = F[:, ::-1].copy()
    return P, F


def _revolved(name: str, profile: FloatArray, ntheta: int, source: str, **extra: object) -> Shape:
    P, F = revolve(profile, ntheta)
    closed = profile[0, 0] <= 0 and profile[-1, 0] <= 0

    def dist(X: FloatArray) -> FloatArray:
        return profile_distance(np.stack([np.hypot(X[:, 0], X[:, 1]), X[:, 2]], 1), profile)

    return _shape(name, P, F, dist, source, closed, **extra)


def cylinder(aspect: float, ntheta: int = 200, height: float = 1.9) -> Shape:
    """Closed cylinder of radius 1: side triangles ``aspect``:1 (axial : chord), caps one fan
    each (valence ``ntheta``)."""
    chord = 2 * np.sin(np.pi / ntheta)
    rows = max(1, round(height / (aspect * chord)))
    prof = _subdivide([(0.0, 0.0), (1.0, 0.0), (1.0, height), (0.0, height)], [1, rows, 1])
    return _revolved(f"cylinder {aspect:g}:1", prof, ntheta,
                     f"closed cylinder r 1, {ntheta} sides, {rows} rows of {aspect:g}:1 "
                     f"triangles, caps fans of valence {ntheta}")


def cup(wall: float, ntheta: int = 96, radius: float = 1.0, height: float = 1.6) -> Shape:
    """Closed thin-walled cup: outer radius 1, wall ``wall`` edges thick (rim and bottom too)."""
    e = 2 * np.pi * radius / ntheta
    t = wall * e
    corners = [(0.0, 0.0), (radius, 0.0), (radius, height), (radius - t, height),
               (radius - t, t), (0.0, t)]
    counts = [max(1, round(radius / e)), max(1, round(height / e)), 2,
              max(1, round((height - t) / e)), max(1, round((radius - t) / e))]
    return _revolved(f"cup wall {wall:g}h", _subdivide(corners, counts), ntheta,
                     f"closed cup, wall {wall:g} edges thick, {ntheta} sides")


def ellipsoid(a: float, c: float, nprof: int = 14, ntheta: int = 28) -> Shape:
    """Coarse closed ellipsoid of revolution (semi-axes ``a``, ``a``, ``c``)."""
    t = np.linspace(0.0, np.pi, nprof + 1)
    prof = np.stack([a * np.sin(t), -c * np.cos(t)], 1)
    prof[[0, -1], 0] = 0.0
    fine = np.linspace(0.0, np.pi, 20001)
    dense = np.stack([a * np.sin(fine), -c * np.cos(fine)], 1)
    P, F = revolve(prof, ntheta)
    rad = np.hypot(P[:, 0], P[:, 1])
    P[:, :2] *= np.where(rad > 0, 1.0, 0.0)[:, None]

    def dist(X: FloatArray) -> FloatArray:
        return profile_distance(np.stack([np.hypot(X[:, 0], X[:, 1]), X[:, 2]], 1), dense)

    return _shape(f"ellipsoid {a:g}x{c:g} coarse", P, F, dist,
                  f"ellipsoid {a:g}, {a:g}, {c:g}: {nprof} x {ntheta} vertices", True)


def extrude(name: str, profile: FloatArray, width: float, ny: int, source: str) -> Shape:
    """``profile`` ((x, z) rows) swept along ``y`` over ``[0, width]`` in ``ny`` rows."""
    m = len(profile)
    y = np.linspace(0.0, width, ny + 1)
    P = np.column_stack([np.tile(profile[:, 0], ny + 1), np.repeat(y, m),
                         np.tile(profile[:, 1], ny + 1)])
    i, j = np.meshgrid(np.arange(ny), np.arange(m - 1), indexing="ij")
    a = (i * m + j).ravel()
    F = np.vstack([np.stack([a, a + 1, a + m + 1], 1), np.stack([a, a + m + 1, a + m], 1)])

    def dist(X: FloatArray) -> FloatArray:
        d = profile_distance(X[:, [0, 2]], profile)
        over = np.maximum(0.0, np.maximum(-X[:, 1], X[:, 1] - width))
        return np.hypot(d, over)

    return _shape(name, P, F.astype(np.int64), dist, source, False)


def fold(gap: float, e: float = 0.05, length: float = 1.5, width: float = 1.2) -> Shape:
    """Hairpin-folded strip: two flat layers ``gap`` edges apart joined by a half circle."""
    g = gap * e
    layer = np.linspace(length, 0.0, round(length / e) + 1)
    arcn = max(3, round(np.pi * g / 2 / e))
    th = np.linspace(-np.pi / 2, np.pi / 2, arcn + 1)[1:-1]
    arc = np.stack([-0.5 * g * np.cos(th), 0.5 * g + 0.5 * g * np.sin(th)], 1)
    prof = np.vstack([np.stack([layer, np.zeros_like(layer)], 1), arc,
                      np.stack([layer[::-1], np.full_like(layer, g)], 1)])
    return extrude(f"fold gap {gap:g}h", prof, width, round(width / e),
                   f"hairpin-folded strip, layers {gap:g} edges apart")


def stairs(steps: int = 5, tread: float = 0.4, rise: float = 0.25, e: float = 0.05,
           width: float = 1.0) -> Shape:
    """90° stairs: ``steps`` treads and risers (vertical noise is the family's)."""
    corners = [(0.0, 0.0)]
    for _ in range(steps):
        x, z = corners[-1]
        corners += [(x + tread, z), (x + tread, z + rise)]
    corners.append((corners[-1][0] + tread, corners[-1][1]))
    counts = [max(1, round(np.hypot(b[0] - a[0], b[1] - a[1]) / e))
              for a, b in itertools.pairwise(corners)]
    return extrude(f"stairs {steps}x{rise:g}", _subdivide(corners, counts), width,
                   round(width / e), f"{steps} 90-degree steps, rise {rise:g}, tread {tread:g}")


def holed_plate(holes: int, side: float = 4.0, e: float = 0.08, radius: float = 0.3,
                seed: int = 3) -> Shape:
    """Square plate with ``holes`` circular holes on a grid (rotated into general position)."""
    g = int(np.ceil(np.sqrt(holes)))
    cen = np.array([((i + 0.5) * side / g, (j + 0.5) * side / g)
                    for i in range(g) for j in range(g)])[:holes]
    t = np.linspace(0.0, side, round(side / e) + 1)[:-1]
    outer = np.vstack([np.stack([t, np.zeros_like(t)], 1), np.stack([np.full_like(t, side), t], 1),
                       np.stack([side - t, np.full_like(t, side)], 1),
                       np.stack([np.zeros_like(t), side - t], 1)])
    m = round(2 * np.pi * radius / e)
    a = 2 * np.pi * np.arange(m) / m
    rims = [c + radius * np.stack([np.cos(a), np.sin(a)], 1) for c in cen]
    rng = np.random.default_rng(seed)
    gx = np.arange(e, side - 0.5 * e, e)
    X, Y = np.meshgrid(gx, gx, indexing="ij")
    inner = np.stack([X.ravel(), Y.ravel()], 1) + rng.uniform(-0.2, 0.2, (X.size, 2)) * e
    dc, _ = cKDTree(cen).query(inner)
    inner = inner[dc > radius + 0.6 * e]
    Q = np.vstack([outer, *rims, inner])
    F = Delaunay(Q).simplices
    dcent, _ = cKDTree(cen).query(Q[F].mean(axis=1))
    F = F[dcent > radius]
    P = np.column_stack([Q - side / 2, np.zeros(len(Q))]) @ _rotation(ANGLES).T
    nrm = _rotation(ANGLES)[:, 2]

    def dist(Xq: FloatArray) -> FloatArray:
        return np.abs((Xq - P[0]) @ nrm)

    return _shape(f"plate {holes} holes", P, F.astype(np.int64), dist,
                  f"{side:g} x {side:g} plate with {holes} holes of radius {radius:g}", False,
                  loops=1 + holes)


def plate(thickness: float, cells: int = 4, m: int = 10) -> Shape:
    """Thin CAD plate ``cells`` x ``cells`` x ``thickness`` (a voxel layer flattened), rotated."""
    P, F = voxel_surface(np.ones((cells, cells, 1), dtype=bool), m)
    P[:, 2] *= thickness
    P = (P - P.mean(axis=0)) @ _rotation(ANGLES).T
    return _shape(f"plate {cells}x{cells}x{thickness:g}", P, F, metrics.SurfaceDistance(P, F),
                  f"thin CAD plate {cells} x {cells} x {thickness:g}, {m}x{m} grid per square",
                  True)


def duplicated_cloud(n: int, fraction: float, seed: int) -> Shape:
    """A sphere cloud whose last ``fraction`` of points repeat earlier ones (the noise is copied
    too: ``extra["copies"]`` holds the pairs)."""
    base = sphere_cloud(n)
    rng = np.random.default_rng(seed)
    src = rng.choice(n, max(1, round(fraction * n)), replace=False)
    base.points = np.vstack([base.points, base.points[src]])
    base.frame = np.concatenate([base.frame, base.frame[src]])
    base.name = f"sphere cloud {n} + {fraction:.1%} duplicates"
    base.extra = {"copies": np.stack([src, n + np.arange(src.size)], 1)}
    return base


def boundary_vertices(F: IntArray, n: int) -> NDArray[np.bool_]:
    """Vertices on an edge that only one face has."""
    E = np.sort(np.vstack([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    u, c = np.unique(E, axis=0, return_counts=True)
    out = np.zeros(n, dtype=bool)
    out[u[c == 1].ravel()] = True
    return out
