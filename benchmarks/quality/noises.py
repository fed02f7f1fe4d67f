"""Noise models of issue 21 beyond ``cases.py``'s normal / iso / aniso / outliers.

Each model is ``noise(shape, level, rng) -> Noise``: the displacement ``E`` added to the clean
points, the true noise level the estimator is scored against and the outlier mask. ``level``
scales the mean spacing ``h`` (``sigma = level * h``) except for ``quant`` (grid step
``level * h``). The true level (``Noise.sigma``) is the RMS standard deviation of the noise *per
normal direction* (what a local fit's residual sees), computed from the model's covariance:

* ``view``: a range scanner: Gaussian noise of std ``sigma`` along the ray from one viewpoint
  (three diameters away, seeded direction); the normal part is ``sigma |n . d|``;
* ``laplace``: i.i.d. Laplace per coordinate with standard deviation ``sigma`` (heavy tail);
* ``student``: Student-t with 3 degrees of freedom per coordinate, scaled to std ``sigma``;
* ``quant``: coordinates rounded to a grid of step ``level * h`` (no other noise; per
  coordinate error uniform on a step: std ``step / sqrt(12)``);
* ``vary``: isotropic Gaussian whose std grows linearly from ``sigma`` to ``5 sigma`` along the
  shape's longest axis (true level: the RMS over the points);
* ``gps``: curves: AR(1) noise along the curve's vertex order (``phi = 0.9`` per sample,
  stationary std ``sigma`` per coordinate), the correlated error of a GPS track;
* ``out3`` / ``out10`` / ``out30``: ``aniso`` bulk noise (``cases.py``) plus 0.5 % of the points
  moved by 3, 10 or 30 spacings in a random direction (the true level is the bulk's).
* ``stray05`` / ``stray1`` / ``stray2`` (issue 31): isotropic Gaussian bulk noise plus 0.5, 1 or
  2 % of the points moved far off the shape: 10 - 50 spacings (uniform) in a random direction,
  redrawn until the stray point lies at least :data:`STRAY_MIN` spacings from the true surface
  (the outlier mask says which; the true level is the bulk's);
* ``clean`` (issue 31): no noise at all (level 0): what the default does to a noise-free input.

Every model draws from the generator it is given (seeded by the case key), so a case is
reproducible on its own.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from benchmarks.quality.shapes import Shape

__all__ = ["NOISE_MODELS", "Noise"]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

TANGENTIAL = 0.2  # aniso bulk under the outliers, as in cases.py
OUTLIER_FRACTION = 0.005
GPS_PHI = 0.9
VARY_MAX = 5.0
VIEW_DISTANCE = 3.0  # viewpoint distance in diameters
STRAY_RANGE = (10.0, 50.0)  # stray distances, in spacings
STRAY_MIN = 5.0  # a stray point is at least this many spacings from the true shape


@dataclass
class Noise:
    """A drawn noise: displacements, true per-normal-direction level, outlier mask."""

    E: FloatArray
    sigma: float
    outliers: BoolArray


def _no_outliers(shape: Shape) -> BoolArray:
    return np.zeros(shape.n, dtype=bool)


def _normal_part(shape: Shape, cov_dir: FloatArray) -> FloatArray:
    """Per point ``|N^T d|^2 / codim`` for unit directions ``d`` (n, s)."""
    N = shape.frame[:, :, : shape.codim]
    return np.einsum("nsc,ns->nc", N, cov_dir) ** 2 @ np.ones(shape.codim) / shape.codim


def _view(shape: Shape, level: float, rng: np.random.Generator) -> Noise:
    P = shape.points
    centre = 0.5 * (P.min(axis=0) + P.max(axis=0))
    diam = float(np.linalg.norm(P.max(axis=0) - P.min(axis=0)))
    u = np.asarray(rng.normal(size=(P.shape[1],)), dtype=np.float64)
    u[-1] = abs(u[-1]) + 1.0  # seen from above (height fields face +z)
    eye = centre + VIEW_DISTANCE * diam * u / np.linalg.norm(u)
    d = P - eye
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    sigma = level * shape.h
    E = sigma * rng.normal(size=(shape.n, 1)) * d
    true = sigma * np.sqrt(np.mean(_normal_part(shape, d)))
    return Noise(E, float(true), _no_outliers(shape))


def _laplace(shape: Shape, level: float, rng: np.random.Generator) -> Noise:
    sigma = level * shape.h
    E = rng.laplace(scale=sigma / np.sqrt(2.0), size=shape.points.shape)
    return Noise(E, sigma, _no_outliers(shape))


def _student(shape: Shape, level: float, rng: np.random.Generator) -> Noise:
    sigma = level * shape.h
    E = sigma / np.sqrt(3.0) * rng.standard_t(3, size=shape.points.shape)  # var(t3) = 3
    return Noise(E, sigma, _no_outliers(shape))


def _quant(shape: Shape, level: float, rng: np.random.Generator) -> Noise:
    step = level * shape.h
    P = shape.points
    E = np.round(P / step) * step - P
    return Noise(E, step / np.sqrt(12.0), _no_outliers(shape))


def _vary(shape: Shape, level: float, rng: np.random.Generator) -> Noise:
    P = shape.points
    axis = int(np.argmax(np.ptp(P, axis=0)))
    t = (P[:, axis] - P[:, axis].min()) / np.ptp(P[:, axis])
    s = level * shape.h * (1.0 + (VARY_MAX - 1.0) * t)
    E = s[:, None] * rng.normal(size=P.shape)
    return Noise(E, float(np.sqrt(np.mean(s**2))), _no_outliers(shape))


def _curve_order(shape: Shape) -> NDArray[np.int64]:
    """Vertices in walking order along the edges (chains concatenated; any start)."""
    assert shape.edges is not None, "gps noise needs a curve"
    nbrs: list[list[int]] = [[] for _ in range(shape.n)]
    for a, b in shape.edges:
        nbrs[a].append(int(b))
        nbrs[b].append(int(a))
    seen = np.zeros(shape.n, dtype=bool)
    order: list[int] = []
    ends = [i for i in range(shape.n) if len(nbrs[i]) == 1]
    for start in [*ends, *range(shape.n)]:
        i = start
        while not seen[i]:
            seen[i] = True
            order.append(i)
            nxt = [j for j in nbrs[i] if not seen[j]]
            if not nxt:
                break
            i = nxt[0]
    return np.asarray(order, dtype=np.int64)


def _gps(shape: Shape, level: float, rng: np.random.Generator) -> Noise:
    sigma = level * shape.h
    order = _curve_order(shape)
    W = rng.normal(size=shape.points.shape) * sigma * np.sqrt(1.0 - GPS_PHI**2)
    Z = np.empty_like(W)
    Z[0] = rng.normal(size=W.shape[1]) * sigma
    for k in range(1, len(Z)):
        Z[k] = GPS_PHI * Z[k - 1] + W[k]
    E = np.empty_like(Z)
    E[order] = Z
    return Noise(E, sigma, _no_outliers(shape))


def _outliers(distance: float) -> Callable[[Shape, float, np.random.Generator], Noise]:
    def noise(shape: Shape, level: float, rng: np.random.Generator) -> Noise:
        sigma = level * shape.h
        n, s = shape.points.shape
        c = shape.codim
        scale = np.r_[np.ones(c), np.full(s - c, TANGENTIAL)]
        E = sigma * np.einsum("nij,nj->ni", shape.frame, rng.normal(size=(n, s)) * scale)
        idx = rng.choice(n, max(1, round(OUTLIER_FRACTION * n)), replace=False)
        d = rng.normal(size=(idx.size, s))
        E[idx] += distance * shape.h * d / np.linalg.norm(d, axis=1, keepdims=True)
        out = np.zeros(n, dtype=bool)
        out[idx] = True
        return Noise(E, sigma, out)

    return noise


def _stray(fraction: float) -> Callable[[Shape, float, np.random.Generator], Noise]:
    def noise(shape: Shape, level: float, rng: np.random.Generator) -> Noise:
        sigma = level * shape.h
        n, s = shape.points.shape
        E = sigma * rng.normal(size=(n, s))
        idx = np.sort(rng.choice(n, max(1, round(fraction * n)), replace=False))
        dist = rng.uniform(*STRAY_RANGE, idx.size) * shape.h
        todo = np.arange(idx.size)
        for _ in range(100):
            d = rng.normal(size=(todo.size, s))
            E[idx[todo]] = dist[todo, None] * d / np.linalg.norm(d, axis=1, keepdims=True)
            near = shape.distance(shape.points[idx[todo]] + E[idx[todo]]) < STRAY_MIN * shape.h
            todo = todo[near]
            if not todo.size:
                break
        out = np.zeros(n, dtype=bool)
        out[idx] = True
        return Noise(E, sigma, out)

    return noise


def _clean(shape: Shape, level: float, rng: np.random.Generator) -> Noise:
    return Noise(np.zeros_like(shape.points), 0.0, _no_outliers(shape))


NOISE_MODELS: dict[str, Callable[[Shape, float, np.random.Generator], Noise]] = {
    "view": _view,
    "laplace": _laplace,
    "student": _student,
    "quant": _quant,
    "vary": _vary,
    "gps": _gps,
    "out3": _outliers(3.0),
    "out10": _outliers(10.0),
    "out30": _outliers(30.0),
    "stray05": _stray(0.005),
    "stray1": _stray(0.01),
    "stray2": _stray(0.02),
    "clean": _clean,
}
