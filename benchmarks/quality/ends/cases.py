"""Experiment cases for issue 21 items 4-5 (curves, grids): built here, not in the benchmark."""

from __future__ import annotations

import zlib

import numpy as np

from benchmarks.quality.cases import Case, make_shape
from benchmarks.quality.curves import (
    PolylineDistance,
    _chain,
    _curve_shape,
    _nonuniform,
    _segments,
    circle2d,
    network2d,
    network3d,
    trefoil3d,
)
from benchmarks.quality.shapes import Shape, frame_from_normal


def torus_knot(p=3, q=5, n=900):
    def f(s):
        r = 2 + np.cos(q * s)
        return np.stack([r * np.cos(p * s), r * np.sin(p * s), -np.sin(q * s)], -1)

    def df(s):
        r = 2 + np.cos(q * s)
        dr = -q * np.sin(q * s)
        return np.stack(
            [
                dr * np.cos(p * s) - p * r * np.sin(p * s),
                dr * np.sin(p * s) + p * r * np.cos(p * s),
                -q * np.cos(q * s),
            ],
            -1,
        )

    t = 2 * np.pi * _nonuniform(n, True, 0.6)
    return _curve_shape(
        "torus knot (3,5)",
        f(t),
        df(t),
        _chain(0, n, True),
        PolylineDistance(_segments(f, 0, 2 * np.pi, 80000)),
        False,
        "",
    )


def helix(n=500, turns=4.0):
    def f(s):
        return np.stack([np.cos(s), np.sin(s), 0.25 * s], -1)

    def df(s):
        return np.stack([-np.sin(s), np.cos(s), 0.25 + 0 * s], -1)

    t = 2 * np.pi * turns * _nonuniform(n, False, 0.5)
    return _curve_shape(
        "helix",
        f(t),
        df(t),
        _chain(0, n),
        PolylineDistance(_segments(f, 0, 2 * np.pi * turns, 40000)),
        False,
        "",
    )


def open_wave(n=400):
    """calibration open curve: a 2-D open wave y = 0.3 sin(3x), x in [0, 2*pi]."""

    def f(s):
        return np.stack([s, 0.3 * np.sin(3 * s)], -1)

    def df(s):
        return np.stack([np.ones_like(s), 0.9 * np.cos(3 * s)], -1)

    t = 2 * np.pi * _nonuniform(n, False, 0.7)
    return _curve_shape(
        "open wave 2-D",
        f(t),
        df(t),
        _chain(0, n),
        PolylineDistance(_segments(f, 0, 2 * np.pi, 40000)),
        False,
        "",
    )


def open_spiral3d(n=500):
    """calibration open 3-D curve: a conical spiral."""

    def f(s):
        r = 0.5 + 0.1 * s
        return np.stack([r * np.cos(s), r * np.sin(s), 0.15 * s], -1)

    def df(s):
        r = 0.5 + 0.1 * s
        return np.stack(
            [0.1 * np.cos(s) - r * np.sin(s), 0.1 * np.sin(s) + r * np.cos(s), 0.15 + 0 * s], -1
        )

    t = 6 * np.pi * _nonuniform(n, False, 0.6)
    return _curve_shape(
        "conical spiral",
        f(t),
        df(t),
        _chain(0, n),
        PolylineDistance(_segments(f, 0, 6 * np.pi, 40000)),
        False,
        "",
    )


def _field(seed, modes=12, rough=1.0):
    rng = np.random.default_rng(seed)
    kx = rng.normal(size=modes) * 2.0
    ky = rng.normal(size=modes) * 2.0
    ph = rng.uniform(0, 2 * np.pi, modes)
    amp = rng.normal(size=modes) / (1 + np.hypot(kx, ky)) ** rough

    def z(x, y):
        return 0.15 * sum(
            a * np.cos(u * x + v * y + p) for a, u, v, p in zip(amp, kx, ky, ph, strict=True)
        )

    def grad(x, y):
        gx = -0.15 * sum(
            a * u * np.sin(u * x + v * y + p) for a, u, v, p in zip(amp, kx, ky, ph, strict=True)
        )
        gy = -0.15 * sum(
            a * v * np.sin(u * x + v * y + p) for a, u, v, p in zip(amp, kx, ky, ph, strict=True)
        )
        return gx, gy

    return z, grad


class HeightDistance:
    """Distance to z = f(x, y): vertical residual / sqrt(1 + |grad f|^2) (first order)."""

    def __init__(self, z, grad):
        self.z, self.grad = z, grad

    def __call__(self, X):
        r = X[:, 2] - self.z(X[:, 0], X[:, 1])
        gx, gy = self.grad(X[:, 0], X[:, 1])
        return np.abs(r) / np.sqrt(1 + gx**2 + gy**2)


def grid_mesh(m, diag="alt"):
    i, j = np.meshgrid(np.arange(m - 1), np.arange(m - 1), indexing="ij")
    a = (i * m + j).ravel()
    b = a + 1
    c = a + m
    d = c + 1
    if diag == "same":
        F = np.vstack([np.column_stack([a, c, b]), np.column_stack([b, c, d])])
    else:
        flip = ((i + j) % 2 == 1).ravel()
        F1 = np.where(flip[:, None], np.column_stack([a, c, d]), np.column_stack([a, c, b]))
        F2 = np.where(flip[:, None], np.column_stack([a, d, b]), np.column_stack([b, c, d]))
        F = np.vstack([F1, F2])
    return F.astype(np.int64)


def terrain(m=60, seed=7, diag="same", name="terrain"):
    z, grad = _field(seed)
    g = np.linspace(-1.5, 1.5, m)
    X, Y = np.meshgrid(g, g, indexing="ij")
    P = np.column_stack([X.ravel(), Y.ravel(), z(X, Y).ravel()])
    gx, gy = grad(X.ravel(), Y.ravel())
    nrm = np.column_stack([-gx, -gy, np.ones_like(gx)])
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    F = grid_mesh(m, diag)
    h = float(g[1] - g[0])
    return Shape(
        name, P, F, None, frame_from_normal(nrm), 1, HeightDistance(z, grad), h, closed=False
    )


def hemisphere():
    s = make_shape("sphere-2.5K")
    keep = s.points[:, 2] > -0.05
    idx = -np.ones(s.n, int)
    idx[keep] = np.arange(keep.sum())
    F = idx[s.faces[keep[s.faces].all(1)]]
    P = s.points[keep]
    from benchmarks import metrics

    return Shape(
        "hemisphere",
        P,
        F,
        None,
        frame_from_normal(P / np.linalg.norm(P, axis=1, keepdims=True)),
        1,
        metrics.sphere_distance,
        s.h,
        closed=False,
    )


SHAPES = {
    "circle-2d": circle2d,
    "trefoil-3d": trefoil3d,
    "network-2d": network2d,
    "network-3d": network3d,
    "wave-2d": open_wave,
    "spiral-3d": open_spiral3d,
    "knot35": torus_knot,
    "helix": helix,
    "terrain": lambda: terrain(60, 7, "same", "terrain"),
    "dem": lambda: terrain(80, 11, "alt", "dem"),
    "hemisphere": hemisphere,
}
_C = {}


def shape(key):
    if key not in _C:
        _C[key] = SHAPES[key]() if key in SHAPES else make_shape(key)
    return _C[key]


def case(key):
    """ "shape/noise-level": noise normal|iso|aniso|quant|zonly."""
    sk, spec = key.split("/")
    noise, lv = spec.rsplit("-", 1)
    level = float(lv)
    sh = shape(sk)
    rng = np.random.default_rng(zlib.crc32(key.encode()))
    n, s = sh.points.shape
    c = sh.codim
    if noise == "quant":
        q = level * sh.h
        off = rng.uniform(0, q, s)
        P = np.round((sh.points + off) / q) * q - off
        sigma = q / np.sqrt(12)
    elif noise == "zonly":
        sigma = level * sh.h
        P = sh.points.copy()
        P[:, 2] += sigma * rng.normal(size=n)
    else:
        sigma = level * sh.h
        G = rng.normal(size=(n, s))
        scale = {
            "normal": np.r_[np.ones(c), np.zeros(s - c)],
            "iso": np.ones(s),
            "aniso": np.r_[np.ones(c), np.full(s - c, 0.2)],
        }[noise]
        P = sh.points + sigma * np.einsum("nij,nj->ni", sh.frame, G * scale)
    return Case(key, sh, noise, level, P, sigma, np.zeros(n, bool))


def density_cloud(n=6000, seed=5):
    """Sphere cloud whose density varies 10:1 from the south to the north pole (held out)."""
    from scipy.spatial import cKDTree

    from benchmarks import metrics

    rng = np.random.default_rng(seed)
    out = []
    while sum(len(o) for o in out) < n:
        v = rng.normal(size=(4 * n, 3))
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        w = 0.1 + 0.9 * (v[:, 2] + 1) / 2
        out.append(v[rng.uniform(size=len(v)) < w])
    P = np.vstack(out)[:n]
    d, _ = cKDTree(P).query(P, k=2)
    return Shape(
        "sphere cloud 10:1",
        P,
        None,
        None,
        frame_from_normal(P),
        1,
        metrics.sphere_distance,
        float(d[:, 1].mean()),
        closed=True,
    )


SHAPES["cloud-density"] = density_cloud
