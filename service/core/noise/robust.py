"""Data weights ``omega_i`` (the diagonal ``D`` of eq. 3) from the noise (issue 21).

Two factors multiply the user's weights ``u_i``:

* **robust** ``rho_i``: each point's leave-one-out residual ``r_i`` against the quadratic fit
  of its neighbours (:mod:`.pointfits`), scaled by the noise, ``z_i = sqrt(r_i) / sigma_i``,
  is ``|N(0, 1)|``-like (``chi_c`` for ``c`` normal directions) for Gaussian noise (the scale
  is calibrated so that the median of ``z_i^2`` is that of ``chi^2_c``). Points with
  ``z_i`` above the Gaussian extreme ``z0`` (:data:`ALPHA` per point) while the fit of their
  neighbours is consistent with the noise (``v_i <= V_MAX sigma_i^2``; a crease or a second
  outlier nearby leaves the point undecided, weight 1) are outliers. Their neighbours' fits are
  made again without them (one pass), so that an outlier does not hide a second one. Points
  far from their neighbours' centroid (:func:`isolated`: thrown inside a sphere or far along
  the surface, where no fit is consistent) are outliers too.
  Weights: ``"huber"`` ``rho^2 = min(1, 1.345 / z)``; ``"tukey"`` ``rho = max(1 - (z/4.685)^2,
  0)``; ``"auto"`` only when more points exceed ``z0`` than Gaussian noise explains (a Poisson
  test on their count, or one point so far out that ``n P(chi^2_c > z^2) < 10^-3``), then
  ``rho = 1`` up to ``z0`` and Tukey's taper to 0 at ``2 z0`` (the bulk keeps its weight).
  Weights never go below :data:`OMEGA_MIN` (the system stays definite).
* **uneven noise** ``s_i = (sigma / sigma_i)^(1/2)`` (:data:`UNEVEN_POWER`): ``sigma_i^2``
  the lower quartile of the ``v_j`` over the point's neighbourhood (bias-corrected by the
  ``chi^2_nu / nu`` quartile; a crease or an outlier raises the fits across it, not the
  quartile), its logarithm averaged over the neighbourhood twice. ``"auto"`` applies it when the
  spread ``q90 - q10`` of ``log sigma_i`` exceeds :data:`SPREAD`, which a constant noise level
  does not reach, and the residuals are noise rather than shape (:data:`SHAPE_FREE`); see
  ``service/core/README.md``, "Issue 21: noise and data weights".

The automatic tau sums ``(omega_i sigma_i / sigma)^2`` (eq. 3's expectation under noise
``sigma_i``): outliers leave the budget, the bulk noise fills it.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from service.core.geometry import Geometry
from service.core.noise.estimate import NoiseEstimate, estimate_noise, manifold_dim
from service.core.noise.pointfits import leave_one_out, point_neighbours
from service.core.noise.quantiles import chi2, poisson_ppf
from service.core.noise.uneven import RATIO_CAP, crease_factor, local_sigma, on_grid, row_quantile
from service.core.operator.sized_kernels import COMPILED_FROM
from service.core.params import DataParams
from service.core.warnings import EngineWarning, warning

__all__ = [
    "ALPHA",
    "OMEGA_MIN",
    "SPREAD",
    "DataWeights",
    "data_weights",
    "flag_outliers",
    "isolated",
    "robust_weights",
]

Array = NDArray[np.float64]


#: Per-point probability of a Gaussian residual beyond the outlier threshold ``z0``.
ALPHA = 1e-4
#: Upper quantile of ``chi^2_nu / nu`` up to which a neighbours' fit is "consistent with the
#: noise" (``v_i <= V_MAX sigma_i^2``).
V_QUANTILE = 1e-3
#: Smallest robust weight.
OMEGA_MIN = 1e-3
#: ``q90 - q10`` of ``log sigma_i`` above which the noise varies (constant noise stays below).
SPREAD = 0.7
#: Outliers with a robust weight up to this are placed by
#: :func:`~service.core.finish.outliers.pull_in`.
PULLED = 0.1
#: A point further than this many local spacings from its neighbours' centroid is isolated.
ISOLATION = 4.0
#: ``"auto"`` noise weights only where the residuals are clearly noise: the estimate's scale
#: ratio ``v(2k) / v(k)`` (:mod:`.noise`) at most this (calibration: smooth shapes with
#: constant or varying noise <= 1.05, the issue-31 varying cloud 1.00; CAD parts with creases
#: under uniform noise 1.07 (6K cube at 0.05 and 0.1 h) - 1.62 (fandisk 0.1 h), where the crease
#: band's fits make the spread 0.8 - 1.3 and the weights smoothed the creases away: 1.15 let
#: the cube through, 1.96x worse than its input).
SHAPE_FREE = 1.05
HUBER, TUKEY = 1.345, 4.685
#: ``s_i = (sigma / sigma_i)^UNEVEN_POWER``: 1 is eq. (3)'s ``D = 1/sigma``; 0.5 measured better
#: (calibration: sphere, circle, cloud sphere with noise 1 -> 5x; ``service/core/README.md``).
UNEVEN_POWER = 0.5


@dataclass(frozen=True)
class DataWeights:
    """The weights a run uses and why.

    Attributes
    ----------
    omega : ndarray, shape (n,)
        ``u_i rho_i s_i`` (finite; fixed points keep theirs).
    tau_scale : ndarray, shape (n,)
        ``sigma_i / sigma``: the automatic tau sums ``(omega_i tau_scale_i)^2``.
    outliers : ndarray of int
        Points treated as outliers (``z_i > z0``, weight reduced).
    robust : str
        The robust rule applied: ``"none"``, ``"huber"``, ``"tukey"`` or ``"auto"``.
    uneven : bool
        Whether ``s_i`` was applied.
    spread : float or None
        ``q90 - q10`` of ``log sigma_i``.
    warnings : tuple of EngineWarning
        The noise weights' (the outliers' warning is the finish stage's record,
        :class:`~service.core.finish.outliers.Outliers`).
    pulled : ndarray of int
        Outliers whose weight is (next to) zero:
        :func:`~service.core.finish.outliers.pull_in` places them.
    """

    omega: Array
    tau_scale: Array
    outliers: NDArray[np.int64]
    robust: str = "none"
    uneven: bool = False
    spread: float | None = None
    warnings: tuple[EngineWarning, ...] = ()
    pulled: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))


def data_weights(
    geometry: Geometry, params: DataParams
) -> tuple[Geometry, DataWeights | None]:
    """The geometry with its weights replaced by ``omega`` of :class:`DataWeights`, and them.

    ``params`` is the plan's data group (``SmoothingParams.data``): ``robust`` and
    ``noise_weights`` are what the run tries, their gates decided
    (:func:`service.core.params.rules.data_weight_gates`, in
    :func:`service.core.plan.make_plan`). ``None``: nothing applies.
    """
    robust, uneven = params.robust, params.noise_weights
    if robust == "none" and uneven == "none":
        return geometry, None
    got = _factors(geometry, robust, uneven)
    if got is None:
        return geometry, None
    rho, ratio, outliers, applied, use_uneven, spread = got
    if params.outliers in ("flag", "drop") and outliers.size:  # no part in tau (issue 31)
        rho = rho.copy()
        rho[outliers] = OMEGA_MIN
    omega = geometry.omega() * rho / ratio**UNEVEN_POWER
    weights = omega if geometry.weights is None else np.where(
        np.isfinite(geometry.weights), omega, geometry.weights)
    said: tuple[EngineWarning, ...] = ()
    if use_uneven:
        said = (warning("uneven-noise", f"noise varies across the input (spread of log sigma_i "
                        f"{spread:.2f}): weights 1/sigma_i", spread=spread, gate=SPREAD),)
    pulled = outliers[(rho[outliers] <= PULLED) & ~geometry.fixed_mask()[outliers]]
    dw = DataWeights(omega, ratio, outliers, applied, use_uneven, spread, said, pulled)
    return replace(geometry, weights=weights), dw


def _factors(
    geometry: Geometry, robust: str, uneven: str
) -> tuple[Array, Array, NDArray[np.int64], str, bool, float] | None:
    """``rho``, ``sigma_i / sigma``, the outliers, the robust rule applied, whether the noise
    weights apply and the spread; coincident points (split normals, repeated scans) are
    measured once (a copy among the neighbours fits the point exactly), as a cloud.

    Surfaces in 3-D from :data:`~service.core.noise.fast_weights.COMPILED_FROM` points take the
    compiled kernels (issue 30: the grid ``k``-NN, whose distances also tell coincident points,
    the fits and the isolation pass; same rules, same numbers to rounding).
    """
    fast = None
    if geometry.n >= COMPILED_FROM:  # fast_weights loads numba: not for a small input
        from service.core.noise import fast_weights

        fast = fast_weights.neighbours(geometry)
    if fast is not None:
        return _from_neighbours(geometry, fast[0], fast[1], fast[2], robust, uneven,
                                compiled=True, dist=fast[3])  # fmt: skip
    P = geometry.points
    uniq, inv = np.unique(P, axis=0, return_inverse=True)
    if uniq.shape[0] < geometry.n:
        if uniq.shape[0] < 10:
            return None
        got = _factors(Geometry(uniq), robust, uneven)
        if got is None:
            return None
        inv = inv.reshape(-1)
        rho, ratio, out, applied, use_uneven, spread = got
        return (rho[inv], ratio[inv], np.flatnonzero(np.isin(inv, out)), applied, use_uneven,
                spread)
    est = estimate_noise(geometry)
    d = manifold_dim(geometry)
    if est is None or not est.noise_found or geometry.dim - d < 1:
        return None
    nbr = point_neighbours(geometry, est.k, d, est.neighbours)
    return _from_neighbours(geometry, est, d, nbr, robust, uneven, compiled=False)


def _from_neighbours(
    geometry: Geometry, est: NoiseEstimate, d: int, nbr: NDArray[np.int64], robust: str,
    uneven: str, compiled: bool, dist: Array | None = None,
) -> tuple[Array, Array, NDArray[np.int64], str, bool, float]:  # fmt: skip
    """:func:`_factors` from each point's neighbours (row ``i``: ``i`` first; ``dist`` their
    distances when known). The quantization check runs only where its answer matters."""
    P = geometry.points
    if compiled:  # numba: only on the compiled path
        from service.core.noise import fast_weights
        from service.core.noise.fast_fits import leave_one_out as fits
    else:
        fits = leave_one_out
    r, v = fits(P, nbr, d)
    c = geometry.dim - d
    nu = max(c * (nbr.shape[1] - 1 - (1 + d + d * (d + 1) // 2)), 1)
    s2 = np.full(geometry.n, est.sigma**2) * _calibration(r, est.sigma**2, c)
    _, r, v = flag_outliers(P, nbr, d, r, v, s2, nu)  # fits without outliers
    sig = (fast_weights.local_sigma if compiled else local_sigma)(v, nbr, nu)
    finite = np.isfinite(sig) & (sig > 0)
    spread = float(np.subtract(*np.quantile(np.log(sig[finite]), [0.9, 0.1]))) if finite.any() \
        else 0.0
    use_uneven = uneven == "local" or (
        uneven == "auto" and spread > SPREAD
        and (est.scale_ratio is None or est.scale_ratio <= SHAPE_FREE)
        and not on_grid(P, est.sigma)
    )  # fmt: skip
    ratio = np.where(finite, sig, est.sigma) / est.sigma if use_uneven else np.ones(geometry.n)
    ratio = np.clip(ratio, 1.0 / RATIO_CAP, RATIO_CAP)
    s2 = (est.sigma * ratio) ** 2
    far = isolated(geometry, nbr, np.sqrt(s2), compiled, dist)
    rho, outliers, applied = robust_weights(
        P, d, r, v, s2 * _calibration(r, s2, c), nu, robust, far
    )
    return rho, ratio * crease_factor(sig, est.sigma), outliers, applied, use_uneven, spread


def _calibration(r: Array, s2: Array | float, c: int) -> float:
    """``median(r / s2)`` over that of ``chi^2_c``: the scale that makes the leave-one-out
    residuals' bulk ``chi^2_c`` (the global estimate is the mode of differently made fits)."""
    with np.errstate(all="ignore"):
        q = np.nanmedian(r / s2)
    return float(np.clip(q / chi2.median(c), 0.25, 4.0)) if np.isfinite(q) and q > 0 else 1.0


def flag_outliers(
    P: Array, nbr: NDArray[np.int64], d: int, r: Array, v: Array, s2: Array, nu: int
) -> tuple[NDArray[np.bool_], Array, Array]:
    """Points beyond the Gaussian extreme of a fit consistent with the noise (``s2`` per point),
    and ``r, v`` with the fits that had outliers among their neighbours made again without."""
    c = max(P.shape[1] - d, 1)
    t0 = float(chi2.isf(ALPHA, c))
    vmax = float(chi2.isf(V_QUANTILE, nu) / nu)
    with np.errstate(invalid="ignore"):
        flagged = (r > t0 * s2) & (v <= vmax * s2)
        again = np.flatnonzero(flagged[nbr[:, 1:]].any(axis=1))
        if again.size:
            r2, v2 = leave_one_out(P, nbr[again], d, ~flagged[nbr[again, 1:]])
            r, v = r.copy(), v.copy()
            r[again], v[again] = r2, v2
            flagged = (r > t0 * s2) & (v <= vmax * s2)
    return flagged, r, v


def isolated(
    geometry: Geometry, nbr: NDArray[np.int64], sigma: Array, compiled: bool = False,
    dist: Array | None = None,
) -> NDArray[np.bool_]:
    """Points far from their neighbours: from the median of their graph neighbours for meshes
    and curves (coordinate-wise, so that a neighbour thrown off does not move it), their mean
    distance to the ``k`` nearest for clouds; beyond :data:`ISOLATION` times the local spacing
    (median over the ``k`` nearest of their mean distance to their own) and beyond twice the
    Gaussian extreme of the noise. A
    point thrown far off (inside a sphere, far along the surface) has neighbours that fit
    nothing, so its residual test is undecided; this catches it. ``compiled``: the distances
    by :func:`service.core.noise.fast_weights.isolated_mask` (compiled, issue 30; from the
    ``k``-NN's distances ``dist`` when given)."""
    z0 = float(np.sqrt(chi2.isf(ALPHA, 1)))
    if compiled:
        from service.core.noise.fast_weights import isolated_mask

        return isolated_mask(geometry, nbr, sigma, ISOLATION, 2 * z0, dist)
    P = geometry.points
    d = np.mean(np.linalg.norm(P[nbr[:, 1:]] - P[:, None, :], axis=2), axis=1)
    spacing = np.median(d[nbr[:, 1:]], axis=1)
    E = geometry.faces if geometry.faces is not None else geometry.edges
    if E is None:  # a cloud: its own mean distance to the k nearest
        return (d > ISOLATION * spacing) & (d > 2 * float(np.sqrt(chi2.isf(ALPHA, 1))) * sigma)
    centre = P.copy()  # a vertex without neighbours is its own centre
    idx = _graph_neighbours(E, geometry.n)
    has = idx[:, 0] >= 0
    Q = np.where((idx >= 0)[..., None], P[np.maximum(idx, 0)], np.nan)[has]
    centre[has] = np.stack([row_quantile(Q[..., a], 0.5) for a in range(P.shape[1])], 1)
    delta = np.linalg.norm(P - centre, axis=1)
    z0 = float(np.sqrt(chi2.isf(ALPHA, 1)))
    return (delta > ISOLATION * spacing) & (delta > 2 * z0 * sigma)


def _graph_neighbours(E: NDArray[np.int64], n: int, most: int = 32) -> NDArray[np.int64]:
    """Each vertex's neighbours over the elements ``E`` (up to ``most``, spread evenly over a
    larger ring: the first ``most`` of a cap's fan of valence 200 are an arc whose median is a
    rim point, issue 40), ``-1`` padded."""
    pairs = np.concatenate([E[:, [a, b]] for a in range(E.shape[1])
                            for b in range(E.shape[1]) if a != b])
    A = sp.csr_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    A.sum_duplicates()
    deg = np.diff(A.indptr)
    m = int(min(max(int(deg.max(initial=0)), 1), most))
    step = np.maximum(deg / m, 1.0)[:, None]
    pos = A.indptr[:-1, None] + (np.arange(m) * step).astype(np.int64)
    ok = np.arange(m) < deg[:, None]
    return np.where(ok, A.indices[np.minimum(pos, max(A.nnz - 1, 0))] if A.nnz else -1, -1)


def robust_weights(
    P: Array, d: int, r: Array, v: Array, s2: Array, nu: int, rule: str,
    far: NDArray[np.bool_] | None = None,
) -> tuple[Array, NDArray[np.int64], str]:
    """``rho_i``, the outliers and the rule applied (module docstring), from the residuals
    ``r, v`` of :func:`flag_outliers`, the noise variance ``s2`` per point and the points
    ``far`` from everything (:func:`isolated`, treated as infinitely far out)."""
    n = P.shape[0]
    ones = np.ones(n)
    if rule == "none":
        return ones, np.zeros(0, np.int64), "none"
    c = max(P.shape[1] - d, 1)
    t0 = float(chi2.isf(ALPHA, c))
    vmax = float(chi2.isf(V_QUANTILE, nu) / nu)
    with np.errstate(invalid="ignore"):
        decided = np.isfinite(r) & (v <= vmax * s2)
        z = np.where(decided, np.sqrt(np.maximum(r, 0.0) / s2), 0.0)
    if far is not None:
        z[far] = np.inf
    z0 = float(np.sqrt(t0))
    outliers = np.flatnonzero(z > z0)
    if rule == "auto":
        top = float(np.max(z, initial=0.0))
        extreme = 0.0 if np.isinf(top) else n * chi2.sf(top**2, c)  # Bonferroni
        if outliers.size <= poisson_ppf(0.999, n * ALPHA) and extreme > 1e-3:
            return ones, np.zeros(0, np.int64), "none"
        t = np.clip((z - z0) / z0, 0.0, 1.0)
        rho = 1.0 - t**2
    elif rule == "huber":
        rho = np.sqrt(np.minimum(1.0, HUBER / np.maximum(z, 1e-300)))
    else:
        rho = 1.0 - (z / TUKEY) ** 2
    return np.maximum(rho, OMEGA_MIN), outliers, rule
