"""Issue 21's new curves: knots, an open helix and a GPS-like track, sampled non-uniformly.

* ``torusknot``: the (3, 5) torus knot on a torus R = 2, r = 0.8 (closed, 3-D);
* ``fig8``: the figure-eight knot ``((2 + cos 2t) cos 3t, (2 + cos 2t) sin 3t, sin 4t)``;
* ``helix``: three turns of ``(cos t, sin t, 0.15 t)`` (open: two free ends);
* ``track``: an open 2-D path (a smooth random curve, a GPS track seen from above).

Distances are exact up to the dense reference polyline (60 000 segments; its chordal error is
below 1e-6 of the shape's size, far under any noise level used).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from benchmarks.quality.curves import PolylineDistance, _chain, _curve_shape, _nonuniform, _segments
from benchmarks.quality.shapes import Shape

__all__ = ["fig8", "helix", "torus_knot", "track"]

FloatArray = NDArray[np.float64]
Curve = Callable[[FloatArray], FloatArray]
DENSE = 60000


def _derivative(f: Curve, t: FloatArray, eps: float = 1e-6) -> FloatArray:
    return (f(t + eps) - f(t - eps)) / (2 * eps)


def _closed(name: str, f: Curve, n: int, source: str) -> Shape:
    t = 2 * np.pi * _nonuniform(n, True)
    return _curve_shape(name, f(t), _derivative(f, t), _chain(0, n, True),
                        PolylineDistance(_segments(f, 0, 2 * np.pi, DENSE)), False, source)


def _open(name: str, f: Curve, t1: float, n: int, source: str) -> Shape:
    t = t1 * _nonuniform(n, False, 0.6)
    return _curve_shape(name, f(t), _derivative(f, t), _chain(0, n),
                        PolylineDistance(_segments(f, 0.0, t1, DENSE)), False, source)


def torus_knot(n: int = 1500, p: int = 3, q: int = 5) -> Shape:
    def f(t: FloatArray) -> FloatArray:
        rr = 2.0 + 0.8 * np.cos(q * t)
        return np.stack([rr * np.cos(p * t), rr * np.sin(p * t), 0.8 * np.sin(q * t)], -1)

    return _closed(f"({p},{q}) torus knot", f, n, f"({p},{q}) torus knot, {n} points, non-uniform")


def fig8(n: int = 1200) -> Shape:
    def f(t: FloatArray) -> FloatArray:
        rr = 2.0 + np.cos(2 * t)
        return np.stack([rr * np.cos(3 * t), rr * np.sin(3 * t), np.sin(4 * t)], -1)

    return _closed("figure-eight knot", f, n, f"figure-eight knot, {n} points, non-uniform")


def helix(n: int = 1000, turns: float = 3.0) -> Shape:
    def f(t: FloatArray) -> FloatArray:
        return np.stack([np.cos(t), np.sin(t), 0.15 * t], -1)

    return _open("helix", f, 2 * np.pi * turns, n, f"open helix, {turns:g} turns, {n} points")


def track(n: int = 2000) -> Shape:
    rng = np.random.default_rng(27)
    k = np.arange(1, 7)
    ax, ay = rng.normal(size=(2, k.size)) / k**1.5
    px, py = rng.uniform(0, 2 * np.pi, (2, k.size))

    def f(t: FloatArray) -> FloatArray:
        s = t[:, None] * k[None]
        return np.stack([t + 0.25 * np.sin(s + px) @ ax, 0.25 * np.sin(s + py) @ ay], -1)

    return _open("track 2-D", f, 2 * np.pi, n, f"open smooth random 2-D path, {n} points")
