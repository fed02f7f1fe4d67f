"""Benchmark cases: a clean shape plus synthetic noise of a known model and level.

Noise models (``sigma = level * h``, ``h`` the shape's mean spacing):

* ``normal``: ``sigma`` along the normal only (each normal direction for curves in 3-D);
* ``iso``: isotropic, ``sigma`` per coordinate;
* ``aniso``: ``sigma`` along the normal plus ``0.2 sigma`` per tangent direction (the issue's
  "0.5 h + 0.1 h" at level 0.5);
* ``outliers``: ``aniso`` plus 1 % of the points displaced by ``4 h`` in a random direction.

The true noise level the estimator is scored against is ``sigma`` (per normal direction).
Seeds come from the case key, so every case is reproducible on its own.
"""

from __future__ import annotations

import zlib
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from benchmarks.quality.curves import circle2d, network2d, network3d, trefoil3d
from benchmarks.quality.families import NEW_SHAPES
from benchmarks.quality.noises import NOISE_MODELS
from benchmarks.quality.shapes import (
    Shape,
    box,
    mesh_cloud,
    real_mesh,
    sphere,
    sphere_cloud,
    torus,
    torus_cloud,
)

__all__ = ["FULL", "QUICK", "SHAPES", "Case", "make_case", "make_shape"]

FloatArray = NDArray[np.float64]
NOISES = ("normal", "iso", "aniso", "outliers")
TANGENTIAL = 0.2
OUTLIER_FRACTION = 0.01
OUTLIER_DISTANCE = 4.0


SHAPES: dict[str, Callable[[], Shape]] = {
    "sphere-642": lambda: sphere(3),
    "sphere-2.5K": lambda: sphere(4),
    "sphere-10K": lambda: sphere(5),
    "sphere-41K": lambda: sphere(6),
    "torus-1.4K": lambda: torus(60, 24),
    "torus-5.8K": lambda: torus(120, 48),
    "torus-40K": lambda: torus(320, 125),
    "box": box,
    "fandisk": lambda: real_mesh("fandisk.obj", "fandisk"),
    "spot": lambda: real_mesh("spot.obj", "spot", weld=True),
    "bunny": lambda: real_mesh("bun_zipper.ply", "bun_zipper"),
    "horse": lambda: real_mesh("horse.ply", "horse"),
    "circle-2d": circle2d,
    "network-2d": network2d,
    "trefoil-3d": trefoil3d,
    "network-3d": network3d,
    "cloud-sphere": sphere_cloud,
    "cloud-torus": lambda: torus_cloud(10000),
    "cloud-fandisk": lambda: mesh_cloud(
        real_mesh("fandisk.obj", "fandisk"), 10000, "fandisk cloud 10K"
    ),
    "cloud-bunny": lambda: mesh_cloud(
        real_mesh("bun_zipper.ply", "bunny"), 20000, "bunny cloud 20K"
    ),
}

_CACHE: dict[str, Shape] = {}


def make_shape(key: str) -> Shape:
    """The clean shape ``key`` of :data:`SHAPES` (built once per process)."""
    if key not in _CACHE:
        _CACHE[key] = (SHAPES[key] if key in SHAPES else NEW_SHAPES[key])()
    return _CACHE[key]


@dataclass
class Case:
    """One benchmark input: noisy points of a clean :class:`Shape`."""

    key: str
    shape: Shape
    noise: str
    level: float
    points: FloatArray
    sigma: float
    outliers: NDArray[np.bool_]

    @property
    def n(self) -> int:
        return self.shape.n

    @property
    def label(self) -> str:
        return f"{self.shape.name}, {self.noise} {self.level:g}h"


def make_case(key: str) -> Case:
    """``"<shape>/<noise>-<level>"``, e.g. ``"sphere-2.5K/aniso-0.5"``.

    Shapes of :data:`SHAPES` or ``families.NEW_SHAPES``; noise models of this module or of
    ``noises.NOISE_MODELS`` (issue 21). A suffix ``#k`` (``"stepblock/iso-0.1#3"``) is another
    draw of the same noise: the seed comes from the whole key.
    """
    shape_key, spec = key.split("/")
    noise, level_s = spec.rsplit("-", 1)
    if noise not in NOISES and noise not in NOISE_MODELS:
        raise KeyError(f"unknown noise {noise!r}")
    level = float(level_s.split("#")[0])
    shape = make_shape(shape_key)
    rng = np.random.default_rng(zlib.crc32(key.encode()))
    if noise in NOISE_MODELS:
        drawn = NOISE_MODELS[noise](shape, level, rng)
        return Case(key, shape, noise, level, shape.points + drawn.E, drawn.sigma, drawn.outliers)
    sigma = level * shape.h
    n, s = shape.points.shape
    c = shape.codim
    G = rng.normal(size=(n, s))
    if noise == "normal":
        scale = np.r_[np.ones(c), np.zeros(s - c)]
    elif noise == "iso":
        scale = np.ones(s)
    else:
        scale = np.r_[np.ones(c), np.full(s - c, TANGENTIAL)]
    E = sigma * np.einsum("nij,nj->ni", shape.frame, G * scale)
    out = np.zeros(n, dtype=bool)
    if noise == "outliers":
        idx = rng.choice(n, max(1, int(OUTLIER_FRACTION * n)), replace=False)
        d = rng.normal(size=(idx.size, s))
        E[idx] += OUTLIER_DISTANCE * shape.h * d / np.linalg.norm(d, axis=1, keepdims=True)
        out[idx] = True
    return Case(key, shape, noise, level, shape.points + E, sigma, out)


def _grid(shapes: list[str], noises: tuple[str, ...], levels: tuple[float, ...]) -> list[str]:
    return [f"{s}/{nz}-{lv:g}" for s in shapes for nz in noises for lv in levels]


_SMALL = ["sphere-2.5K", "torus-5.8K", "box", "fandisk", "spot", "circle-2d", "trefoil-3d",
          "cloud-sphere"]
_LEVELS = (0.1, 0.25, 0.5)

#: The full benchmark: every noise model x level on the small shapes, the resolution series and
#: the large real meshes and clouds at the issue's noise (aniso 0.5 h), outliers on a few.
FULL: list[str] = (
    _grid(_SMALL, ("normal", "iso", "aniso"), _LEVELS)
    + _grid(["sphere-642", "sphere-10K", "sphere-41K", "torus-1.4K", "torus-40K"], ("aniso",),
            (0.5,))
    + _grid(["bunny", "horse", "network-2d", "network-3d", "cloud-torus", "cloud-fandisk",
             "cloud-bunny"], ("aniso",), (0.5,))
    + _grid(["sphere-2.5K", "fandisk", "circle-2d", "cloud-sphere"], ("outliers",), (0.25,))
)

#: ``--quick``: one case per kind of input.
QUICK: list[str] = [
    "sphere-2.5K/aniso-0.5",
    "torus-5.8K/aniso-0.5",
    "fandisk/aniso-0.25",
    "spot/iso-0.25",
    "circle-2d/aniso-0.5",
    "network-3d/aniso-0.5",
    "cloud-sphere/aniso-0.5",
    "sphere-2.5K/outliers-0.25",
]
