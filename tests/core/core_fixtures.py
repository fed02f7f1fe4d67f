"""Small synthetic inputs for the core tests (a plain module: tests/ has no packages)."""

from __future__ import annotations

import numpy as np
import trimesh
from numpy.typing import NDArray


def noisy_icosphere(subdivisions: int, sigma: float, seed: int = 0) -> tuple[NDArray, NDArray]:
    m = trimesh.creation.icosphere(subdivisions)
    rng = np.random.default_rng(seed)
    return m.vertices + rng.normal(0.0, sigma, m.vertices.shape), np.asarray(m.faces)


def grid_mesh(nx: int, ny: int, jitter: float = 0.0, seed: int = 0) -> tuple[NDArray, NDArray]:
    """Planar triangulated grid in the z = 0 plane; interior vertices jittered in the plane."""
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.linspace(0, 1, nx), np.linspace(0, 1, ny))
    P = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    interior = (x.ravel() > 0) & (x.ravel() < 1) & (y.ravel() > 0) & (y.ravel() < 1)
    P[interior, :2] += rng.uniform(-jitter, jitter, (interior.sum(), 2)) / max(nx, ny)
    idx = np.arange(nx * ny).reshape(ny, nx)
    a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    c, d = idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    faces = np.concatenate([np.column_stack([a, b, d]), np.column_stack([a, d, c])])
    return P, faces


def polyline_edges(n: int, closed: bool = False, offset: int = 0) -> NDArray:
    i = np.arange(n - (0 if closed else 1))
    return np.column_stack([i, (i + 1) % n]) + offset


def random_rotation(dim: int, seed: int = 0) -> NDArray:
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(dim, dim)))
    return q


def planned_weights(geometry, params):  # type: ignore[no-untyped-def]
    """The data weights of ``params`` as a run computes them: the plan decides the gates
    (issue 38), :func:`service.core.noise.robust.data_weights` applies them."""
    from service.core.noise.robust import data_weights
    from service.core.plan import make_plan

    return data_weights(geometry, make_plan(geometry, params).params.data)
