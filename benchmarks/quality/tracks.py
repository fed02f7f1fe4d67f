"""Issue 31's GPS-like tracks: straight legs joined by 90, 45 and 135 degree turns (2-D, open),
sampled at uneven spacing along the path (as a receiver logging at a fixed rate while the
speed changes: gaps drawn from a gamma law, coefficient of variation 0.5).

:func:`recorded_track` (issue 31's "resampled real track"): the recorded
``korita-zbevnica.obj`` (3-D, its three segments joined end to end in file order: one open
polyline) taken as the true path, resampled at uneven spacing (the same gamma gaps) with about
one sample per :data:`RECORDED_STEP` metres; the distance is to the recorded polyline.

The true track is the polygon itself, so the distance to it is exact
(:class:`~benchmarks.quality.curves.PolylineDistance` on the polygon's legs cut into short
collinear pieces, which only narrows the KD-tree's candidates). Each sample's tangent is its
leg's direction. The noise of the family is ``gps`` (AR(1) along the track,
:mod:`~benchmarks.quality.noises`).
"""

from __future__ import annotations

import itertools

import numpy as np
from numpy.typing import NDArray

from benchmarks.quality.curves import PolylineDistance, _chain, _curve_shape
from benchmarks.quality.shapes import Shape

__all__ = ["TRACKS", "corner_track", "recorded_track", "track_a", "track_b"]

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


#: Mean spacing (metres) of :func:`recorded_track`'s resampling.
RECORDED_STEP = 8.0


def recorded_track() -> Shape:
    """The recorded GPS track as the true path, resampled (module docstring)."""
    from benchmarks.shapes import data_dir
    from service.io import read_geometry

    g = read_geometry(f"{data_dir()}/korita-zbevnica.obj").geometry
    V = g.points[np.unique(np.asarray(g.edges))]  # the segments in file order, joined
    seg = np.linalg.norm(np.diff(V, axis=0), axis=1)
    V = np.vstack([V[:1], V[1:][seg > 0]])
    cum = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(V, axis=0), axis=1))]
    n = int(cum[-1] / RECORDED_STEP)
    gaps = np.random.default_rng(33).gamma(1.0 / GAP_CV**2, GAP_CV**2, n - 1)
    s = np.r_[0.0, np.cumsum(gaps)] * cum[-1] / gaps.sum()
    leg = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(V) - 2)
    d = (V[leg + 1] - V[leg]) / (cum[leg + 1] - cum[leg])[:, None]
    P = V[leg] + (s - cum[leg])[:, None] * d
    pieces = []
    for a, b in itertools.pairwise(V):
        t = np.linspace(0.0, 1.0, max(2, int(np.linalg.norm(b - a) / 0.5)) + 1)[:, None]
        q = a + t * (b - a)
        pieces.append(np.stack([q[:-1], q[1:]], axis=1))
    return _curve_shape("recorded track", P, d, _chain(0, n), PolylineDistance(np.vstack(pieces)),
                        False, f"korita-zbevnica.obj as the true path (3-D), {n} samples at "
                        f"uneven spacing (gamma gaps, CV {GAP_CV}, mean {RECORDED_STEP} m)")
