"""The tangential step: the along-surface part of the noise, removed after the normal solve.

Normal-only displacement (:mod:`.displacement`) cannot touch noise along the surface; with
isotropic noise that is two thirds of it, and the result stays at about 0.8 of the input's
vertex error (issue 21). Moving points along the surface is only right when the data show
along-surface noise: on a clean but irregular sampling, the tangential part of ``L X`` is the
sampling itself, and relaxing it moves points away from their true positions (a pure-normal-noise
icosphere goes from 0.14 to 0.70 of the input's vertex error when the free solution's tangential
part is added at the normal solve's lambda). So the step is sized by the data:

1. **The tangential share** ``rho`` (:func:`tangential_share`): white noise shows in ``L_u P``
   (the uniform Laplacian) with the same per-direction size along the normal and along the
   surface; the robust (median) ratio of the two, each scaled by the median of its
   ``chi^2`` distribution, estimates ``sigma_t / sigma_n``: ~1 for isotropic noise, ~0.2 for the
   benchmark's anisotropic noise, 0.05 - 0.5 for noise along the normals only (the sampling's own
   irregularity and the normals' error leak into the tangent planes).
2. **The budget** (:func:`tangential_budget`): the discrepancy principle on the tangent
   planes, ``d`` tangent directions against one normal direction, scaled down by
   :data:`BUDGET_FACTOR` and with the share above a floor only
   (``tau_t = BUDGET_FACTOR d phi_n (rho^2 - rho_0^2) / (1 - rho_0^2)``, ``phi_n`` the normal
   solve's deviation; ``rho_0`` :data:`SHARE_FLOOR`, or :data:`SHARE_FLOOR_REGULAR` on regular
   connectivity). Below the floor nothing moves.
3. **The steps** (:func:`tangential_flow`): explicit umbrella steps projected onto the tangent
   planes, from the input, until their deviation ``psi = sum_i omega_i^2 ||e_i||^2`` reaches
   ``tau_t``; the result is added to the normal solve's points. The normal solve moved each
   point along its normal ``n_i`` only, so the total deviation is ``phi_n + psi``.
4. **No new folds** (:func:`unfold`): a face folded after the step that was not folded in the
   normal solve's result shrinks the moves of its corners (and, if that is not enough, of
   their neighbours) back towards the normal solve's positions.
5. **Irregular connectivity** (:func:`valence_irregularity` above :data:`IRREGULAR_VALENCE`):
   no step; there the sampling reads as tangential noise.

Constants chosen on the in-repo shapes of the quality benchmark (sphere, torus, box, spot,
fandisk, bunny) and triangulated random points; ``service/core/README.md``, "Issue 21:
tangential noise".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from service.core.finish.folds import fold_mask
from service.core.finish.volume import edge_counts
from service.core.frame import Frame
from service.core.geometry import Geometry
from service.core.operator.build import SmoothingOperator
from service.core.search.roots import LambdaSearch
from service.core.system.displacement import normal_frames

__all__ = [
    "BUDGET_FACTOR",
    "SHARE_FLOOR",
    "SHARE_FLOOR_REGULAR",
    "TangentialStep",
    "relax_tangential",
    "tangential_budget",
    "tangential_flow",
    "tangential_share",
    "unfold",
    "valence_irregularity",
]

Array = NDArray[np.float64]
#: Tangential shares up to this are read as the sampling's irregularity and the normals' error,
#: not noise. Calibration half, noise along the normals: rho 0.03 - 0.15 on sphere, torus, box
#: and fandisk, up to 0.50 on spot.obj (an irregular remeshing) at 0.1 h; 10 % margin above it.
#: Isotropic noise: 0.81 - 1.04. The benchmark's anisotropic noise (0.2 sigma along the surface,
#: rho 0.21 - 0.53) is left to the normal solve.
SHARE_FLOOR = 0.55
#: The floor on regular connectivity (``valence_irregularity <= REGULAR_VALENCE``: sphere, torus,
#: box), whose own sampling adds little: noise along the normals reads 0.03 - 0.11 there.
SHARE_FLOOR_REGULAR = 0.15
REGULAR_VALENCE = 0.01
#: Shares above this count as this: noise larger along the surface than across it is not what a
#: sensor makes; the excess is the sampling's irregularity (an irregular triangulation) or
#: quantization along flat axis-aligned faces. Calibration half, isotropic noise: 0.81 - 1.04.
SHARE_CAP = 1.0
#: Fraction of the discrepancy budget spent along the surface. Past the full budget the solve
#: relaxes the sampling towards the uniform Laplacian's equilibrium and the vertex error rises
#: steeply (calibration half, isotropic noise, geometric mean of the vertex error with the
#: explicit steps: 0.7 x 0.432, 0.9 x 0.392, 1.1 x 0.413, 1.3 x 0.502; with the Tikhonov solve
#: 0.8 x 0.409, 1.0 x 0.372, 1.25 x 0.459, 1.5 x 0.559).
BUDGET_FACTOR = 0.9
#: Meshes whose connectivity is irregular keep normal-only displacement: the fraction of
#: interior vertices whose valence is not one of the two most common ones. On a random
#: triangulation the sampling's own tangential Laplacian is as large and as white as noise of
#: 0.2 h, the share reads 0.85 - 1.97 under noise along the normals only, and the step made the
#: vertex error 1.07 - 1.45 of the input's (from 0.24 - 0.43). Calibration: sphere, torus, box,
#: hemisphere, terrain and DEM grids 0 - 0.003, fandisk 0.076, spot 0.117, bunny 0.132 (noise
#: along the normals: shares <= 0.50, unchanged), horse 0.181; triangulated random points on a
#: sphere (convex hull, two seeds) 0.44.
IRREGULAR_VALENCE = 0.15
#: Step of the explicit tangential Laplacian steps (the umbrella operator's stable 1/2).
STEP = 0.5
#: At most this many steps (calibration half: 2 - 9 reach the budget).
MAX_STEPS = 200
MEDIAN_CHI2_1 = 0.4549  # median of chi^2 with 1 degree of freedom
MEDIAN_CHI2_2 = 1.3863  # ... with 2 (2 ln 2)


@dataclass(frozen=True)
class TangentialStep:
    """What the tangential step did.

    Attributes
    ----------
    share : float
        ``rho``, the estimated ``sigma_t / sigma_n``.
    budget : float
        ``tau_t`` (internal frame), 0 when the share is below :data:`SHARE_FLOOR`.
    psi : float
        The tangential deviation ``sum_i omega_i^2 ||x_i - x_i^n||^2`` of the result (after
        :func:`unfold`); the total deviation is the normal solve's ``phi`` plus ``psi``.
    steps : int
        Explicit steps taken (:func:`tangential_flow`), 0 when none.
    reverted : int
        Points sent back to the normal solve's position by :func:`unfold`.
    irregular : float
        :func:`valence_irregularity` of the mesh (above :data:`IRREGULAR_VALENCE` no step).
    """

    share: float
    budget: float
    psi: float = 0.0
    steps: int = 0
    reverted: int = 0
    irregular: float = 0.0

    def to_dict(self, phi_factor: float = 1.0) -> dict[str, float | int]:
        """Input-frame numbers (``phi_factor`` of :class:`~service.core.frame.Frame`)."""
        return {
            "share": self.share,
            "budget": self.budget * phi_factor,
            "psi": self.psi * phi_factor,
            "steps": self.steps,
            "reverted": self.reverted,
            "irregular": self.irregular,
        }


def tangential_share(points: Array, adjacency: sp.csr_matrix, normals: Array) -> float:
    """``rho``: the per-direction size of ``L_u P`` along the surface over that along the normal.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    adjacency : scipy.sparse.csr_matrix, shape (n, n)
        The mesh's edge graph (``L_u = I - Deg^-1 A``).
    normals : ndarray, shape (n, 3)
        Unit normals.

    Returns
    -------
    float
        ``sqrt((med ||T^T L_u P||^2 / m_2) / (med (n^T L_u P)^2 / m_1))``, ``m_k`` the median
        of ``chi^2_k``: 1 for white isotropic noise; 0 when the normal part vanishes.
    """
    deg = np.asarray(adjacency.sum(axis=1)).ravel()
    ok = deg > 0
    inv = np.divide(1.0, deg, out=np.zeros_like(deg), where=ok)
    LP = (points - np.asarray((sp.diags(inv) @ adjacency) @ points))[ok]
    across = np.einsum("ij,ij->i", LP, normals[ok]) ** 2
    along = np.maximum(np.sum(LP**2, axis=1) - across, 0.0)
    med_n = float(np.median(across)) / MEDIAN_CHI2_1 if across.size else 0.0
    med_t = float(np.median(along)) / MEDIAN_CHI2_2 if along.size else 0.0
    return float(np.sqrt(med_t / med_n)) if med_n > 0 else 0.0


def valence_irregularity(faces: NDArray[np.int64], n: int) -> float:
    """Fraction of the interior vertices whose valence is neither of the two most common ones.

    0 on regular triangulations (valence 6, or 4 and 8 on grids with alternating diagonals, and
    the few valence-5 vertices of an icosphere), about 0.44 on triangulated random points.
    """
    a, b, counts = edge_counts(faces, n)
    valence = np.bincount(np.concatenate([a, b]), minlength=n)
    boundary = np.zeros(n, dtype=bool)
    boundary[a[counts == 1]] = True
    boundary[b[counts == 1]] = True
    v = valence[~boundary & (valence > 0)]
    if v.size == 0:
        return 0.0
    top = np.sort(np.bincount(v))[-2:].sum()
    return float(1.0 - top / v.size)


def tangential_budget(
    share: float, phi_normal: float, dims: int = 2, floor: float = SHARE_FLOOR
) -> float:
    """``tau_t = BUDGET_FACTOR dims phi_n (rho^2 - rho_0^2) / (1 - rho_0^2)``, 0 below the floor.

    ``phi_n`` is what the normal solve spent on one normal direction; white noise of
    ``sigma_t = rho sigma_n`` holds ``rho^2`` times that per tangent direction (discrepancy
    principle). Shares up to ``floor`` (:data:`SHARE_FLOOR`, or :data:`SHARE_FLOOR_REGULAR`
    on regular connectivity) are not counted.
    """
    if not share > floor or not phi_normal > 0:
        return 0.0
    share = min(share, SHARE_CAP)
    excess = (share**2 - floor**2) / (1.0 - floor**2)
    return float(BUDGET_FACTOR * dims * phi_normal * excess)


def tangential_flow(
    L: sp.csr_matrix,
    P: Array,
    omega: Array,
    fixed: NDArray[np.bool_],
    normals: Array,
    budget: float,
) -> tuple[Array, int, float]:
    """Explicit tangential Laplacian steps from ``P`` until ``psi = budget``.

    ``E <- E - STEP T T^T (L (P + E))`` on the free points (``T T^T`` the projection onto the
    tangent planes of the input, normals ``normals``), the step that would pass the budget
    shortened to land on ``psi = sum_i omega_i^2 ||e_i||^2 = budget`` (a quadratic in its
    length). The iteration count is the regularization (Landweber); it measured as good as
    the tangential part of eq. (4)'s solution at the same budget (calibration half, isotropic
    noise, geometric mean of the vertex error 0.392 against 0.393) at a tenth of the cost.

    Returns
    -------
    E : ndarray, shape (m, s)
        Tangential deviation of the free points.
    steps : int
    psi : float
    """
    free: NDArray[np.bool_] | slice = ~fixed if fixed.any() else slice(None)  # views if all
    d2 = (omega[free] ** 2)[:, None]
    X = P.copy()
    E = np.zeros((int((~fixed).sum()), P.shape[1]))
    psi = 0.0
    for steps in range(1, MAX_STEPS + 1):
        LX = np.asarray(L @ X)[free]
        G = np.einsum("ij,ij->i", LX, normals)[:, None] * normals  # -STEP T T^T (L X), in place
        G = np.multiply(np.subtract(LX, G, out=G), -STEP, out=G)
        tmp = E + G  # d2 (E + G)^2 in place: the same numbers, one temporary
        after = float(np.sum(np.multiply(np.square(tmp, out=tmp), d2, out=tmp)))
        if after >= budget * (1.0 - 1e-12):  # psi(t) = psi + 2t <E, G> + t^2 |G|^2 = budget
            a, b = float(np.sum(d2 * G**2)), 2.0 * float(np.sum(d2 * E * G))
            t = (-b + np.sqrt(max(b * b + 4.0 * a * (budget - psi), 0.0))) / (2.0 * a)
            E += min(max(t, 0.0), 1.0) * G
            return E, steps, float(np.sum(d2 * E**2))
        E += G
        X[free] += G
        psi = after
    return E, MAX_STEPS, psi


def unfold(X: Array, base: Array, faces: NDArray[np.int64], halvings: int = 6) -> tuple[Array, int]:
    """``X`` with the moves from ``base`` shrunk where they fold a face that ``base`` does not.

    The corners of every newly folded face have their move ``X - base`` halved (from the
    fourth round on also their neighbours across the faces), for ``halvings`` rounds; then
    set to zero, a ring wider each round, until no new fold is left. It ends: a face whose
    corners are all back at ``base`` is folded only if it is folded in ``base``.

    Returns
    -------
    X : ndarray
        With no face folded that is not folded in ``base``.
    reverted : int
        Points whose move was shrunk.
    """
    n = X.shape[0]
    before = fold_mask(base, faces, n)
    move = X - base
    scale = np.ones(n)
    for k in range(n + halvings + 1):
        Y = base + scale[:, None] * move
        new = fold_mask(Y, faces, n) & ~before
        if not new.any():
            return Y, int(np.sum(scale < 1))
        mark = np.zeros(n, dtype=bool)
        mark[faces[new].ravel()] = True
        if k >= 3:
            mark[faces[mark[faces].any(axis=1)].ravel()] = True
        scale[mark] = 0.5 * scale[mark] if k < halvings else 0.0
    return base.copy(), n  # not reached


def relax_tangential(
    geometry: Geometry,
    enabled: bool,
    op: SmoothingOperator,
    fixed: NDArray[np.bool_],
    frame: Frame,
    X: Array,
    normal: LambdaSearch,
) -> tuple[Array, TangentialStep | None]:
    """The points ``X`` of the normal solve (input frame) with the tangential step applied.

    Parameters
    ----------
    geometry, op, fixed, frame
        Of the run (:class:`~service.core.problem.Problem`).
    enabled : bool
        The plan's choice (:attr:`service.core.plan.Plan.tangential`).
    X : ndarray, shape (n, 3)
        The normal solve's points.
    normal : LambdaSearch
        Its deviation ``phi_n`` (internal frame).

    Returns
    -------
    X : ndarray
    step : TangentialStep or None
        ``None`` when the step does not apply (the plan's choice).
    """
    if not enabled or not (~fixed).any():
        return X, None
    faces: NDArray[np.int64] = geometry.faces  # type: ignore[assignment]
    irregular = valence_irregularity(faces, geometry.n)
    if irregular > IRREGULAR_VALENCE:
        return X, TangentialStep(0.0, 0.0, irregular=irregular)
    P = frame.points(geometry.points)
    normals = normal_frames(P, op.neighborhoods.adjacency, 1)[:, :, 0]
    share = tangential_share(P, op.neighborhoods.adjacency, normals)
    floor = SHARE_FLOOR_REGULAR if irregular <= REGULAR_VALENCE else SHARE_FLOOR
    budget = tangential_budget(share, normal.phi, floor=floor)
    if budget <= 0:
        return X, TangentialStep(share, budget, irregular=irregular)
    omega = geometry.omega() / frame.weight_scale
    free: NDArray[np.bool_] | slice = ~fixed if fixed.any() else slice(None)  # views if all
    E_t, steps, _ = tangential_flow(op.L, P, omega, fixed, normals[free], budget)
    base = frame.points(X)
    out = base.copy()
    out[free] += E_t
    out, reverted = unfold(out, base, faces)
    psi = float(np.sum((omega[free] ** 2)[:, None] * (out - base)[free] ** 2))
    X = X.copy()
    X[free] = frame.back(out[free])
    return X, TangentialStep(share, budget, psi, steps, reverted, irregular)
