"""Noise level estimation: the standard deviation sigma of the noise across the shape.

For each point, its ``k`` nearest neighbours (the point included) are expressed in a local
frame from principal component analysis: ``d`` tangent coordinates ``u`` (``d`` = 2 for
surfaces, 1 for curves) and ``c = s - d`` normal coordinates ``z``. A quadratic height function
``z(u)`` with ``p = 1 + d + d(d+1)/2`` coefficients is fitted by least squares; its residual sum
of squares divided by the degrees of freedom, ``v_i = RSS_i / (c (k - p))``, is an unbiased
estimate of ``sigma^2`` wherever the shape is locally smooth (the quadratic absorbs the
curvature, the ``k - p`` the part of the noise the fit itself explains). Neighbourhoods across
creases, corners, junctions or outliers give larger values. For ``sigma^2 chi^2_nu / nu``
variates the mode of ``log v`` is exactly ``log sigma^2``, so the estimate is the mode of
``log v_i`` (a kernel density on a histogram): contaminated neighbourhoods only add a tail, even
when they are the majority (on the benchmark's subdivided box more than half of the points are
within two spacings of an edge).

Measured on the quality benchmark (``benchmarks/quality``, 88 cases with known sigma): within
+-15 % on 95 % of the cases; see ``benchmarks/quality/README.md``.

**Noise or shape?** A local fit cannot tell measurement noise from detail of the shape finer
than its neighbourhood (a generalised coastline, a CAD outline sampled at its corners, a coarse
clean mesh): both leave residuals. They differ across scales: the residual variance of noise
does not depend on the neighbourhood size (``v_i`` is unbiased for ``sigma^2`` at any ``k``),
that of shape grows with it (like ``k^3`` on a smooth surface, ``k^5`` on a smooth curve,
``k^(2H)`` on a fractal one). So the points whose ``v_i`` made the mode are fitted again with
``2k`` neighbours and the median of ``v_i(2k) / v_i(k)`` over them
(``NoiseEstimate.scale_ratio``) decides: up to :data:`NOISE_RATIO` the residual is noise,
above it the shape's own detail and the estimate
is ``sigma = 0`` ("no noise found"; the local roughness is kept in
:attr:`NoiseEstimate.roughness`). Measured on noisy and noise-free benchmark shapes and real
files (``service/core/README.md``, "Noise or shape").
"""

from __future__ import annotations

import weakref
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import gaussian_filter1d

from service.core.geometry import Geometry
from service.core.noise import curves
from service.core.noise.curves import TrackNoise
from service.core.noise.pointfits import (
    across,
    adjacency,
    curve_neighbours,
    mesh_neighbours,
    patch_variances,
)

__all__ = [
    "NOISE_RATIO",
    "NoiseEstimate",
    "codimension",
    "estimate_noise",
    "hutchinson_trace",
    "log_mode",
    "manifold_dim",
    "noise_of",
]

SAMPLE = 20000
#: The sample key's frequency (in RMS radii): neighbours differ by thousands of radians, so
#: the sample is spread over the shape like a random one.
SAMPLE_FREQUENCY = 7919.0 * 13.0
#: Largest median ratio ``v_i(2k) / v_i(k)`` still read as noise (calibration half: noisy
#: inputs <= 1.55, noise-free >= 2.21; see ``service/core/README.md``).
NOISE_RATIO = 1.85
#: Degree of the fits with ``2k`` neighbours. Cubic was tried: it lets a coarsely sampled helix
#: with noise 0.09 h pass (quadratic x2.44, cubic x2.26: no) but clean fandisk.obj and spot.obj
#: too (x4.74 -> x1.16, x6.49 -> x1.69), so quadratic.
SCALE_DEGREE = 2
Array = NDArray[np.float64]


@dataclass(frozen=True)
class NoiseEstimate:
    """Estimated noise across the shape.

    Attributes
    ----------
    sigma : float
        Standard deviation of the noise along each normal direction.
    manifold_dim : int
        Dimension ``d`` of the local fits (2 surfaces, 1 curves).
    k : int
        Neighbours per local fit.
    points_used : int
        Points whose fit was well posed.
    residuals : ndarray
        Residual variances ``v_i`` of the fitted neighbourhoods (all points, or a sample of
        :data:`SAMPLE` on large inputs; ``nan`` where no fit was made); the mode of their
        logarithm is ``log sigma^2``.
    roughness : float
        ``sqrt`` of that mode: the local roughness, noise or not (``sigma`` when noise is found).
    scale_ratio : float or None
        Median of ``v_i(2k) / v_i(k)`` over the points near the mode (``None`` when the input
        has fewer than ``2k`` points): about 1 for noise, growing with the shape's detail.
    neighbours : ndarray of int or None
        Every point's ``2k`` nearest (itself first; along the curves for polylines) when the
        fits covered every point in order (reused by :mod:`.robust`), else ``None``.
    """

    sigma: float
    manifold_dim: int
    k: int
    points_used: int
    residuals: NDArray[np.float64]
    roughness: float = 0.0
    scale_ratio: float | None = None
    neighbours: NDArray[np.int64] | None = None
    #: Correlated noise along a polyline (:mod:`.curves`); ``sigma`` is then its level.
    track: TrackNoise | None = None

    @property
    def noise_found(self) -> bool:
        """Whether the residuals are noise (``sigma > 0``) rather than exact or shape detail."""
        return self.sigma > 0

    def describe(self) -> str:
        """One line for the report: the estimate and the evidence behind it."""
        if self.track is not None:
            t = self.track
            return (
                f"noise found: sigma = {self.sigma:.6g}, correlated along the curve (AR(1), "
                f"phi = {t.phi:.2f}; {len(t.modes)} scales, misfit {t.misfit:.3f})"
            )
        if self.sigma > 0:
            ratio = (
                ""
                if self.scale_ratio is None
                else (
                    f"; residuals x{self.scale_ratio:.2f} from {self.k} to {2 * self.k} "
                    "neighbours: "
                    "noise"
                )
            )
            return f"noise found: sigma = {self.sigma:.6g}{ratio}"
        if self.roughness == 0 or self.scale_ratio is None:
            return "no noise found: the input is exactly smooth (local fits leave no residual)"
        return (
            f"no noise found: the local roughness {self.roughness:.3g} grows with the "
            f"neighbourhood (x{self.scale_ratio:.2f} from {self.k} to {2 * self.k} neighbours, "
            f"noise would stay near x1, above x{NOISE_RATIO} it is the shape's own detail)"
        )


def log_mode(values: NDArray[np.float64], bins: int = 512) -> float:
    """Mode of ``log(values)`` by a Gaussian kernel density (Scott's bandwidth) on a histogram.

    For ``sigma^2 chi^2_nu / nu`` variates the mode of the logarithm is exactly
    ``log sigma^2``; neighbourhoods across creases, corners and outliers only add a tail.
    """
    y = np.log(values[values > 0])
    if y.size == 0:
        return float("nan")
    lo, hi = np.quantile(y, [0.005, 0.995])
    if hi - lo <= 1e-9 * max(abs(lo), abs(hi), 1.0):  # all equal to rounding (a regular clean
        return float(np.exp(np.median(y)))  # shape): no histogram of 512 bins fits in that
    hist, edges = np.histogram(y, bins=bins, range=(lo, hi))
    width = edges[1] - edges[0]
    bw = 1.06 * float(np.std(y[(y >= lo) & (y <= hi)])) * y.size ** (-0.2)
    dens = gaussian_filter1d(hist.astype(np.float64), max(bw / width, 1.0), mode="constant")
    centres = 0.5 * (edges[:-1] + edges[1:])
    return float(np.exp(centres[int(np.argmax(dens))]))


def _sample(P: Array) -> NDArray[np.int64]:
    """The points whose neighbourhoods are fitted: all, or :data:`SAMPLE` of them on large
    inputs (the mode of 20000 variances is as sharp as that of more), chosen by a key that is
    a function of the geometry, not of the index order (issue 38: a renumbered mesh sampled
    by index got another sigma^): the fractional part of ``K rho_i`` with ``rho_i`` the
    distance to the centroid over the RMS radius (invariant under rigid motions, scaling and
    renumbering; :func:`~service.core.search.risk.invariant_radius` computes the same)."""
    n = P.shape[0]
    if n <= SAMPLE:
        return np.arange(n)
    centred = P - P.mean(axis=0)
    rho = np.sqrt(np.einsum("ij,ij->i", centred, centred))
    rho /= max(float(np.sqrt(np.mean(rho**2))), 1e-300)
    key = np.modf(rho * SAMPLE_FREQUENCY)[0]
    return np.sort(np.argsort(key, kind="stable")[:SAMPLE])


def manifold_dim(geometry: Geometry) -> int:
    if geometry.faces is not None:
        return 2
    if geometry.edges is not None:
        return 1
    return min(2, geometry.dim - 1)


_MEMO: list[tuple[weakref.ref[Array], tuple[int | None, float], NoiseEstimate | None]] = []


def estimate_noise(geometry: Geometry, k: int | None = None) -> NoiseEstimate | None:
    """:func:`noise_of`, remembered for the last points array (the data weights and the
    automatic tau of one run ask for the same estimate; geometries differing in weights only
    share their points array)."""
    key = (k, float(np.sum(geometry.points)))  # an array changed in place is not the same
    for ref, kk, est in _MEMO:
        if ref() is geometry.points and kk == key:
            return est
    est = noise_of(geometry, k)
    _MEMO[:] = [(weakref.ref(geometry.points), key, est)]
    return est


def noise_of(geometry: Geometry, k: int | None = None) -> NoiseEstimate | None:
    """Robust estimate of the noise standard deviation across the shape.

    Parameters
    ----------
    geometry : Geometry
        Meshes and point clouds are treated as surfaces (curves in 2-D), polylines as curves.
    k : int, optional
        Neighbours per local fit (default: 20 for surfaces, 8 for curves).

    Returns
    -------
    NoiseEstimate or None
        ``None`` when the input is too small or too degenerate for any fit (e.g. 1-D data,
        fewer points than a quadratic needs).
    """
    d = manifold_dim(geometry)
    s = geometry.dim
    c = s - d
    if d < 1 or c < 1:
        return None
    k = k or (12 if d == 2 else 10)
    n = geometry.n
    p = 1 + d + d * (d + 1) // 2
    k = min(k, n)
    if k < p + 2:
        return None
    P = geometry.points
    if geometry.faces is None and geometry.edges is not None:
        rows, along = curve_neighbours(geometry, 2 * k, _sample(geometry.points))
        if along.shape[0] >= max(10, min(P.shape[0], SAMPLE) // 10):
            full = rows.size == n  # every point, in order: kept for the data weights
            return _tracked(geometry, _kept(_estimate(P, along, k, d), along if full else None))
        # mostly polylines shorter than 2k points: neighbours in space, as for clouds
    if geometry.faces is not None and d == 2:
        got = _along_mesh(geometry, k, d)
        if got is not None:
            return got
    from service.core.operator.knn import nearest

    at = _sample(P)
    dist, _ = nearest(P, at, 2, k + 1)  # k-d tree, or the data weights' grid (issue 30)
    if np.any(dist[:, 1] == 0):  # coincident points (split normals, STL): one sample each
        P = np.unique(P, axis=0)
        if P.shape[0] < k:
            return None
        at = _sample(P)
    k2 = min(2 * k, P.shape[0])
    _, nbr = nearest(P, at, k2, k + 1)
    full = P is geometry.points and at.size == n
    return _kept(_estimate(P, nbr, k, d), nbr if full else None)


def _along_mesh(geometry: Geometry, k: int, d: int) -> NoiseEstimate | None:
    """The estimate from the nearest in space, except where they jumped across the mesh
    (:func:`.pointfits.across`: a thin plate, wall or fold, thin triangles) and the
    neighbourhood along the mesh is taken (:func:`.pointfits.mesh_neighbours`), so the two
    sides of a thin part never share one; coincident vertices welded;
    ``None`` (neighbours in space, as for clouds) when fewer than a tenth of the sampled
    vertices have ``2k`` within a few hops (a triangle soup)."""
    P = geometry.points
    F = np.asarray(geometry.faces)
    uniq, inv = np.unique(P, axis=0, return_inverse=True)
    welded = uniq.shape[0] < P.shape[0]
    if welded:
        P, F = uniq, inv.reshape(-1)[F]
    at = _sample(P)
    K = min(2 * k, P.shape[0])
    kept, ring = mesh_neighbours(P, F, K, at)
    if kept.size < max(10, at.size // 10):
        return None
    from service.core.operator.knn import nearest

    _, nbr = nearest(P, kept, K, k + 1)
    jump = across(adjacency(P.shape[0], F), kept, nbr)
    nbr[jump] = ring[jump]
    full = not welded and kept.size == geometry.n
    return _kept(_estimate(P, nbr, k, d), nbr if full else None)


def _kept(est: NoiseEstimate | None, nbr: NDArray[np.int64] | None) -> NoiseEstimate | None:
    return est if est is None or nbr is None else replace(est, neighbours=nbr)


def _tracked(geometry: Geometry, est: NoiseEstimate | None) -> NoiseEstimate | None:
    """``est`` with the correlated noise of :func:`.curves.track_noise` when it explains the
    residual modes at ``k``, 2k, 4k, 8k samples (a GPS-like track), else ``est`` unchanged."""
    if est is None or est.roughness <= 0 or (est.scale_ratio or np.inf) > curves.TRACK_RATIO_MAX:
        return est
    ks = tuple(est.k * s for s in curves.SCALES)
    modes = [est.roughness**2]
    for rows, count in curves.chain_windows(geometry, ks[1:], SAMPLE * est.k):
        if count < max(10, geometry.n // 10):
            return est
        v = patch_variances(geometry.points, rows, 1)
        modes.append(log_mode(v[np.isfinite(v)]))
    t = curves.track_noise(modes, ks) if np.all(np.isfinite(modes)) else None
    return est if t is None else replace(est, sigma=t.sigma, track=t)


def _estimate(P: Array, nbr: NDArray[np.int64], k: int, d: int) -> NoiseEstimate | None:
    """The estimate from neighbourhoods ``nbr`` (nearest first, ``k`` or more per row)."""
    k2 = nbr.shape[1]
    if nbr.shape[0] == 0 or k2 < k:
        return None
    v = patch_variances(P, nbr[:, :k], d)
    ok = np.isfinite(v)
    if ok.sum() < max(10, v.size // 10):
        return None
    extent = float(np.ptp(P, axis=0).max())
    if np.mean(v[ok] <= (1e-12 * extent) ** 2) > 0.5:  # exactly smooth (e.g. a CAD mesh)
        return NoiseEstimate(0.0, d, k, int(ok.sum()), v)
    sigma2 = log_mode(v[ok])
    ratio = _scale_ratio(P, nbr, v, sigma2, d) if k2 >= k + 4 else None
    sigma = float(np.sqrt(sigma2)) if ratio is None or ratio <= NOISE_RATIO else 0.0
    return NoiseEstimate(sigma, d, k, int(ok.sum()), v, float(np.sqrt(sigma2)), ratio)


def _scale_ratio(P: Array, nbr: NDArray[np.int64], v: Array, mode: float, d: int) -> float | None:
    """Median of ``v_i(K) / v_i(k)`` (``K`` = ``nbr``'s width) over the points whose
    ``v_i(k)`` is within a factor ``e`` of the mode: about 1 for noise, larger for shape."""
    with np.errstate(divide="ignore", invalid="ignore"):
        near = np.isfinite(v) & (v > 0) & (np.abs(np.log(v / mode)) < 1.0)
    if near.sum() < 5:
        return None
    v2 = patch_variances(P, nbr[near], d, SCALE_DEGREE)
    good = np.isfinite(v2)
    if good.sum() < 5:
        return None
    return float(np.median(v2[good] / v[near][good]))


# --- tau from the noise: discrepancy principle, generalized cross-validation --------------------


def codimension(geometry: Geometry) -> int:
    """Normal directions per point: ``s - 2`` for meshes, ``s - 1`` for curves and clouds."""
    return max(geometry.dim - manifold_dim(geometry), 0)


def hutchinson_trace(apply: Callable[[Array], Array], m: int, probes: int, seed: int = 0) -> float:
    """Hutchinson's estimate ``mean z^T A z`` of ``tr(A)`` with Rademacher probes ``z``.

    ``apply`` maps an ``(m, probes)`` block to ``A`` times it (one multi-column solve). For the
    residual operators of smoothing (eigenvalues in ``[0, 1]``) the relative standard error is
    at most ``sqrt(2 / (probes tr A))``: below 1 % for 8 probes once ``tr A > 2500``.
    """
    Z = np.random.default_rng(seed).choice([-1.0, 1.0], size=(m, probes))
    return float(np.mean(np.sum(Z * apply(Z), axis=0)))
