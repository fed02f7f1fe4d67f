"""Issue 31's GPS-like tracks: straight legs joined by 90, 45 and 135 degree turns (2-D, open),
sampled at uneven spacing along the path (as a receiver logging at a fixed rate while the
speed changes: gaps drawn from a gamma law, coefficient of variation 0.5).

The true track is the polygon itself, so the distance to it is exact
(:class:`~benchmarks.quality.curves.PolylineDistance` on the polygon's legs cut into short
collinear pieces, which only narrows the KD-tree's candidates). Each sample's tangent is its
leg's direction. The noise of the family is ``gps`` (AR(1) along the track,
:mod:`~benchmarks.quality.noises`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from benchmarks.quality.curves import PolylineDistance, _chain, _curve_shape
from benchmarks.quality.shapes import Shape

__all__ = ["TRACKS", "corner_track", "track_a", "track_b"]

FloatArray = NDArray[np.float64]
GAP_CV = 0.5

#: (legs' lengths, signed turns in degrees after each leg but the last, seed of the spacing)
TRACKS: dict[str, tuple[tuple[float, ...], tuple[float, ...], int]] = {
    "a": ((3.0, 2.0, 2.5, 1.5, 3.0, 2.0, 2.5), (90.0, -45.0, 135.0, -90.0, 45.0, -135.0), 31),
    "b": ((2.5, 3.0, 1.5, 2.0, 2.5, 3.0, 2.0), (-45.0, 90.0, 45.0, -135.0, 90.0, 135.0), 32),
}


def _polygon(legs: tuple[float, ...], turns: tuple[float, ...]) -> FloatArray:
    heading = 0.0
    pts = [np.zeros(2)]
    for k, length in enumerate(legs):
        pts.append(pts[-1] + length * np.array([np.cos(heading), np.sin(heading)]))
        if k < len(turns):
            heading += np.radians(turns[k])
    return np.asarray(pts)


def corner_track(name: str, n: int = 1500) -> Shape:
    """Track ``name`` of :data:`TRACKS` with ``n`` unevenly spaced samples (ends included)."""
    legs, turns, seed = TRACKS[name]
    V = _polygon(legs, turns)
    cum = np.r_[0.0, np.cumsum(legs)]
    rng = np.random.default_rng(seed)
    gaps = rng.gamma(1.0 / GAP_CV**2, GAP_CV**2, n - 1)
    s = np.r_[0.0, np.cumsum(gaps)] * cum[-1] / gaps.sum()
    leg = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(legs) - 1)
    d = (V[leg + 1] - V[leg]) / np.asarray(legs)[leg, None]
    P = V[leg] + (s - cum[leg])[:, None] * d
    pieces = []
    for a, b, length in zip(V[:-1], V[1:], legs, strict=True):
        t = np.linspace(0.0, 1.0, max(2, int(length / 0.005)) + 1)[:, None]
        q = a + t * (b - a)
        pieces.append(np.stack([q[:-1], q[1:]], axis=1))
    angles = ", ".join(f"{t:+g}" for t in turns)
    return _curve_shape(f"corner track {name}", P, d, _chain(0, n),
                        PolylineDistance(np.vstack(pieces)), False,
                        f"2-D track, {len(legs)} straight legs, turns {angles} degrees, {n} "
                        f"samples at uneven spacing (gamma gaps, CV {GAP_CV})")


def track_a() -> Shape:
    return corner_track("a")


def track_b() -> Shape:
    return corner_track("b")
