"""Correlated noise along polylines (GPS-like tracks): sigma^, the noise test, the corners.

A receiver's position error is correlated from one fix to the next; along a track it is close
to an AR(1) sequence ``e_j = phi e_(j-1) + w_j`` of stationary standard deviation ``sigma``
per coordinate (correlation ``phi^m`` at ``m`` samples). A local quadratic fit of ``k``
consecutive samples absorbs most of such a slowly wandering error, so its residual variance
is not ``sigma^2`` (white noise) but

    E[v(k)] = sigma^2 g_k(phi),   g_k(phi) = tr((I - H_k) R(phi)) / (k - p)        (1)

with ``H_k`` the fit's hat matrix, ``R(phi)_ij = phi^|i-j|`` and ``p = 3``: ``g_10(0.9) =
0.116``, which is why the white-noise estimate of :mod:`.estimate` read ``0.32 - 0.35 sigma``
on such tracks, and ``g_20 / g_10`` grows to 1.72 at ``phi = 0.9`` (white noise: 1), which is
why the noise test's cut-off (1.85) was reached by a few corners more.

**The curve's test.** The modes ``m(K)`` of ``log v_i(K)`` at ``K = k, 2k, 4k, 8k``
consecutive samples (:data:`SCALES`; windows along the chains, :func:`chain_windows`) are
fitted by (1): for each ``phi`` of a grid ``sigma^2`` is the
geometric mean of ``m(K) / g_K(phi)``, the misfit the RMS of ``log(m(K) / (sigma^2
g_K(phi)))``. A mode is the value most windows share, so corners, which are few and isolated,
only add a tail at every scale (a window straddling a corner), while noise, which is
everywhere, sets the mode. Shape detail does not follow (1): (1) saturates at ``sigma^2`` once
``K`` exceeds the correlation length, shape keeps growing (``K^5`` smooth, ``K^2H`` fractal).
A fit with ``phi >= PHI_MIN`` and misfit ``<= FIT_TOL`` is correlated noise: ``sigma`` and
``phi`` are those of the fit. Anything else leaves :mod:`.estimate`'s white-noise estimate and
test as they were (white noise gives ``phi`` near 0: the estimate stands, unchanged).

**Smoothing a track.** The automatic tau's discrepancy budget takes this ``sigma`` (a point
moves by about ``sigma`` when its noise is removed) and no tangential share: the weights are
reciprocal (chord lengths carry little of a correlated noise, and uniform weights slide unevenly
spaced samples along the track), and the corners are held (below). Without the corners held and
with uniform weights, the same budget rounded the corners (vertex error up to 2.4 x the input's).

**Corners kept**: the points where the track turns by more than :data:`CORNER_ANGLE` between
the chords ``p_i - p_(i-s)`` and ``p_(i+s) - p_i`` (``s = k / 2``), with the turn concentrated
there (at least :data:`CONCENTRATED` of the turn over ``2s``: a smooth bend turns about twice
as much over twice the length), local maxima of that turn over ``+-s``, are held in place (as
the ends of an open track) with the automatic tau: the legs between them are smoothed, the
corner is not rounded, and it is not reported as an outlier
(:func:`service.core.problem.held_corners`). Measurements: ``service/core/README.md``, "Tracks".
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from service.core.geometry import Geometry

__all__ = [
    "CONCENTRATED",
    "CORNER_ANGLE",
    "FIT_TOL",
    "PHI_MIN",
    "SCALES",
    "TRACK_RATIO_MAX",
    "TRACK_WEIGHTS_WHY",
    "TrackNoise",
    "ar1_factor",
    "chain_windows",
    "track_corners",
    "track_noise",
    "track_pins",
]

#: Multiples of ``k`` whose residual modes are fitted by eq. (1).
SCALES = (1, 2, 4, 8)
#: Smallest fitted correlation read as correlated noise (below: the white-noise estimate).
PHI_MIN = 0.7
#: Largest RMS log misfit of eq. (1) across :data:`SCALES` still read as correlated noise.
FIT_TOL = 0.15
#: Largest ``v(2k) / v(k)`` of the white-noise test for which eq. (1) is fitted at all: AR(1)
#: noise gives at most ``g_20 / g_10`` = 1.76 (``phi`` 0.95), the calibration tracks 1.55 - 1.86
#: (corners add a little); shape 3.0 (coastline) - 6.3 (the recorded track, clean) and more.
TRACK_RATIO_MAX = 2.5
#: The grid of ``phi`` searched.
PHI_GRID = np.round(np.linspace(0.0, 0.95, 96), 4)
#: Why a track's weights are reciprocal (the plan's ``weights`` with the automatic tau).
TRACK_WEIGHTS_WHY = (
    "reciprocal: a track with correlated noise (noise/curves.py); its chord lengths carry "
    "little of the noise, so they keep unevenly spaced samples in place along the track"
)
#: Turn (degrees) between the chords over ``k / 2`` samples either side of a corner.
CORNER_ANGLE = 30.0
#: A corner's turn over ``s`` is at least this share of its turn over ``2s``.
CONCENTRATED = 0.7
Array = NDArray[np.float64]


@dataclass(frozen=True)
class TrackNoise:
    """Correlated noise found along the curves.

    Attributes
    ----------
    sigma : float
        Stationary standard deviation of the AR(1) noise per normal direction (eq. 1's fit).
    phi : float
        Its correlation from one sample to the next.
    removable : float
        White-equivalent level ``sqrt(m(k))``: what the white-noise estimate read.
    misfit : float
        RMS log misfit of eq. (1) across :data:`SCALES`.
    modes : tuple of float
        ``m(K)`` at ``K = k * SCALES``.
    """

    sigma: float
    phi: float
    removable: float
    misfit: float
    modes: tuple[float, ...]


@lru_cache(maxsize=256)
def ar1_factor(k: int, phi: float, p: int = 3) -> float:
    """``g_k(phi)`` of eq. (1) for ``k`` equally spaced samples and a quadratic fit."""
    u = np.linspace(-1.0, 1.0, k)
    B = np.stack([u**j for j in range(p)], axis=1)
    M = np.eye(k) - B @ np.linalg.pinv(B)
    j = np.arange(k)
    R = phi ** np.abs(j[:, None] - j[None, :]).astype(np.float64)
    return float(np.trace(M @ R @ M) / (k - p))


def fit_ar1(modes: Array, ks: tuple[int, ...]) -> tuple[float, float, float]:
    """``(sigma^2, phi, misfit)`` of eq. (1) to the modes ``m(K)`` at ``K`` in ``ks``."""
    best = (float("nan"), 0.0, float("inf"))
    logm = np.log(modes)
    for phi in PHI_GRID:
        logg = np.log([ar1_factor(K, float(phi)) for K in ks])
        s2 = float(np.mean(logm - logg))
        mis = float(np.sqrt(np.mean((logm - logg - s2) ** 2)))
        if mis < best[2]:
            best = (float(np.exp(s2)), float(phi), mis)
    return best


def track_noise(modes: list[float], ks: tuple[int, ...]) -> TrackNoise | None:
    """Correlated noise along the polylines, or ``None`` (module docstring).

    Parameters
    ----------
    modes : list of float
        The modes ``m(K)`` of the residual variances of fits to ``K`` consecutive samples
        (``service.core.noise.estimate._tracked``).
    ks : tuple of int
        The ``K``: ``k`` times :data:`SCALES`.

    Returns
    -------
    TrackNoise or None
        ``None`` when eq. (1) does not explain the growth of the modes across scales with a
        correlation of at least :data:`PHI_MIN`.
    """
    s2, phi, misfit = fit_ar1(np.asarray(modes), ks)
    if phi < PHI_MIN or misfit > FIT_TOL or not np.isfinite(s2):
        return None
    return TrackNoise(float(np.sqrt(s2)), phi, float(np.sqrt(modes[0])), misfit, tuple(modes))


def track_corners(geometry: Geometry, k: int) -> NDArray[np.bool_]:
    """Corners of the polylines: turns above :data:`CORNER_ANGLE` between the chords over
    ``s = k // 2`` samples either side, local maxima over ``+-s`` (module docstring)."""
    n = geometry.n
    out = np.zeros(n, dtype=bool)
    E = np.asarray(geometry.edges)
    deg = np.bincount(E.ravel(), minlength=n)
    s = max(k // 2, 1)
    P = geometry.points
    for chain in _chains(E, deg, n):
        if chain.size < 2 * s + 1:
            continue
        Q = P[chain]
        a = Q[s:-s] - Q[: -2 * s]
        b = Q[2 * s :] - Q[s:-s]
        cos = np.sum(a * b, axis=1) / np.maximum(
            np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1), 1e-300
        )
        turn = np.full(chain.size, 0.0)
        turn[s:-s] = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
        wide = np.full(chain.size, np.inf)  # the turn over 2s: about turn for a corner,
        if chain.size > 4 * s:  # about twice it on a smooth bend
            a2, b2 = Q[2 * s : -2 * s] - Q[: -4 * s], Q[4 * s :] - Q[2 * s : -2 * s]
            c2 = np.sum(a2 * b2, axis=1) / np.maximum(
                np.linalg.norm(a2, axis=1) * np.linalg.norm(b2, axis=1), 1e-300
            )
            wide[2 * s : -2 * s] = np.degrees(np.arccos(np.clip(c2, -1.0, 1.0)))
        turn[turn < CONCENTRATED * wide] = 0.0
        pad = np.pad(turn, s, constant_values=-1.0)
        win = np.lib.stride_tricks.sliding_window_view(pad, 2 * s + 1)
        peak = (turn >= win.max(axis=1)) & (turn > CORNER_ANGLE)
        out[chain[peak]] = True
    return out


def chain_windows(
    geometry: Geometry, ks: tuple[int, ...], budget: int
) -> list[tuple[NDArray[np.int64], int]]:
    """Windows of ``K`` consecutive points along the chains of the polylines (between ends
    and junctions; around closed loops) for each ``K`` of ``ks``, and how many there are: one
    per point of every chain of at least ``K`` points (clipped at open ends), of which at most
    ``budget / K`` are returned (evenly spread: neighbouring windows share most of their
    points). The neighbourhoods of
    eq. (1)'s larger scales, without the hop-by-hop search of
    :func:`service.core.noise.pointfits.curve_neighbours`."""
    E = np.asarray(geometry.edges)
    n = geometry.n
    chains = _chains(E, np.bincount(E.ravel(), minlength=n), n)
    out = []
    for K in ks:
        rows = []
        for chain in chains:
            loop = chain.size > 2 and chain[0] == chain[-1]
            c = chain[:-1] if loop else chain
            if c.size < K:
                continue
            j = np.arange(c.size)[:, None]
            if loop:
                rows.append(c[(j - K // 2 + np.arange(K)) % c.size])
            else:
                rows.append(c[np.clip(j - K // 2, 0, c.size - K) + np.arange(K)])
        W = np.vstack(rows) if rows else np.zeros((0, K), dtype=np.int64)
        count, keep = W.shape[0], max(1, budget // K)
        if count > keep:
            W = W[np.linspace(0, count - 1, keep).astype(np.int64)]
        out.append((W, count))
    return out


def _chains(E: NDArray[np.int64], deg: NDArray[np.int64], n: int) -> list[NDArray[np.int64]]:
    """The runs of degree-2 points between ends and junctions (closed loops from any point)."""
    nbrs: list[list[int]] = [[] for _ in range(n)]
    for a, b in E:
        nbrs[int(a)].append(int(b))
        nbrs[int(b)].append(int(a))
    seen = np.zeros(n, dtype=bool)
    chains = []
    starts = [i for i in range(n) if deg[i] != 2] + list(range(n))
    for start in starts:
        if deg[start] == 2 and seen[start]:
            continue
        for first in nbrs[start]:
            if seen[first] and deg[first] == 2:
                continue
            chain, prev, cur = [start], start, first
            while deg[cur] == 2 and not seen[cur] and cur != start:
                seen[cur] = True
                chain.append(cur)
                nxt = [j for j in nbrs[cur] if j != prev]
                prev, cur = cur, (nxt[0] if nxt else cur)
            chain.append(cur)
            chains.append(np.asarray(chain, dtype=np.int64))
        seen[start] = True
    return chains


def track_pins(geometry: Geometry, track: TrackNoise | None, k: int) -> NDArray[np.bool_]:
    """The corners held in place in a run (:func:`track_corners`) of a polyline whose noise is
    correlated (``track``, from :func:`track_noise`); none otherwise."""
    if track is None or geometry.faces is not None or geometry.edges is None:
        return np.zeros(geometry.n, dtype=bool)
    return track_corners(geometry, k)
