"""The :class:`Problem` of a run: what every analysis sets up before lambda, and the frame
conversions of tau, phi and lambda into and out of the internal frame (:mod:`.frame`).

:func:`prepare`: neighbourhoods and ``L`` (report section 4) -> the free points (fixed ones
eliminated, section 8) -> data weights -> the smoothing system of the chosen displacement mode
(eq. 4, or its normal-only form), in the internal frame.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from service.core.errors import ParameterError
from service.core.finish.volume import check_preservable
from service.core.frame import Frame
from service.core.geometry import Geometry
from service.core.noise.curves import track_pins
from service.core.noise.estimate import estimate_noise
from service.core.noise.robust import DataWeights, data_weights
from service.core.operator.build import SmoothingOperator, build_operator, operator_key
from service.core.params import SmoothingParams
from service.core.params.groups import OperatorParams, field_names
from service.core.system.deviation import SmoothingSystem
from service.core.system.displacement import auto_system, normal_mode
from service.core.system.elimination import laplacian_system
from service.core.warnings import EngineWarning, warning

__all__ = ["Problem", "free_set", "held_corners", "is_track", "prepare", "smoothing_system"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Problem:
    """Everything a run sets up before lambda (the opening every analysis shares).

    Attributes
    ----------
    geometry : Geometry
        With the data weights ``omega_i`` applied (issue 21).
    params : SmoothingParams
        The plan's (``"auto"`` choices resolved), with the displacement actually used.
    op : SmoothingOperator
        Neighbourhoods, weights, ``L`` (sections 2-4).
    fixed : ndarray of bool, shape (n,)
        Points eliminated from the system (section 8), see :func:`free_set`.
    n_fixed : int
        Points fixed by the input or ``fix_boundary``.
    frame : Frame
        The internal frame, weighted by the free points' ``omega``.
    system : SmoothingSystem
        Eq. (4) (or the normal-displacement system) in that frame.
    to_points : callable
        From the system's solution ``U`` to the free points (still in the frame).
    weights : DataWeights or None
        The robust and noise data weights, when any apply.
    warnings : tuple of EngineWarning
        What setting it up found the user should know (in run order).
    """

    geometry: Geometry
    params: SmoothingParams
    op: SmoothingOperator
    fixed: NDArray[np.bool_]
    n_fixed: int
    frame: Frame
    system: SmoothingSystem
    to_points: Callable[[Array], Array]
    weights: DataWeights | None = None
    warnings: tuple[EngineWarning, ...] = ()

    def tau_in(self, tau: float) -> float:
        """A budget of the input in the internal frame: ``tau / (s w)^2``."""
        return self.frame.tau_in(tau)

    def phi_out(self, phi: float) -> float:
        """A deviation of the internal frame in the input's numbers: ``(s w)^2 phi``."""
        return self.frame.phi_out(phi)

    def lam_in(self, lam: float) -> float:
        """``lambda' = lambda w^2 s^(2p)``."""
        return self.frame.lam_in(lam)

    def lam_out(self, lam: float) -> float:
        """The input's lambda of an internal ``lambda'``."""
        return self.frame.lam_out(lam)

    def points(self, U: Array) -> Array:
        """The input's points with the free ones moved to the solution ``U`` of the system."""
        X = self.geometry.points.copy()
        X[~self.fixed] = self.frame.back(self.to_points(U))
        return X


def prepare(
    geometry: Geometry,
    params: SmoothingParams,
    requested: str,
    *,
    operator: SmoothingOperator | None = None,
    step: Callable[[str], None] | None = None,
) -> Problem:
    """Neighbourhoods and ``L`` -> free points -> data weights -> the system of the mode.

    Parameters
    ----------
    geometry : Geometry
    params : SmoothingParams
        The plan's (:attr:`service.core.plan.Plan.params`: displacement resolved).
    requested : str
        The displacement the caller asked for (``"auto"`` may fall back to free displacement
        for an input already smooth across itself, :func:`auto_system`).
    operator : SmoothingOperator, optional
        Built for this geometry and operator group (reuse across tau).
    step : callable, optional
        Told ``"weights"`` when the neighbourhoods are built (progress, :meth:`.Run.step`).
    """
    op = _operator(geometry, params, operator)
    corners = held_corners(geometry, params)
    fixed, n_fixed = free_set(geometry, op, params.fix_boundary, params.preserve_volume, corners)
    said = _boundary_ignored(op, params)
    if step is not None:
        step("weights")
    geometry, weights = data_weights(geometry, params.data)  # robust, noise weights (issue 21)
    weights = _corners_kept(weights, corners)
    said += () if weights is None else weights.warnings
    frame = op.frame.weighted(geometry.omega()[~fixed])
    params, system, to_points = auto_system(
        params, requested, lambda p: smoothing_system(geometry, op, fixed, frame, p)
    )
    return Problem(geometry, params, op, fixed, n_fixed, frame, system, to_points, weights, said)


def _boundary_ignored(op: SmoothingOperator, params: SmoothingParams) -> tuple[EngineWarning, ...]:
    """The warning that ``fix_boundary`` means nothing on k-NN neighbourhoods."""
    if not params.fix_boundary or op.neighborhoods.source != "knn":
        return ()
    return (warning("fix-boundary-ignored",
                    "fix_boundary has no effect on k-NN neighbourhoods (no boundary defined)"),)


def is_track(geometry: Geometry, tau_rule: str) -> bool:
    """Whether the automatic tau (``tau_rule``) smooths a polyline whose noise is correlated
    along it (:mod:`service.core.noise.curves`: corners held, reciprocal weights)."""
    if tau_rule != "auto" or geometry.faces is not None or geometry.edges is None:
        return False
    est = estimate_noise(geometry)
    return est is not None and est.track is not None


def held_corners(geometry: Geometry, params: SmoothingParams) -> NDArray[np.bool_]:
    """A track's corners held in place with the automatic tau (issue 31;
    :func:`service.core.noise.curves.track_pins`); none on other inputs and rules."""
    if not is_track(geometry, params.tau_rule):
        return np.zeros(geometry.n, dtype=bool)
    est = estimate_noise(geometry)
    return track_pins(geometry, None if est is None else est.track, est.k if est else 0)


def _corners_kept(
    weights: DataWeights | None, corners: NDArray[np.bool_]
) -> DataWeights | None:
    """``weights`` without the outliers that are held corners: a corner is shape."""
    if weights is None or not corners[weights.outliers].any():
        return weights
    out = weights.outliers[~corners[weights.outliers]]
    return replace(weights, outliers=out, pulled=weights.pulled[~corners[weights.pulled]])


def _operator(
    geometry: Geometry, params: SmoothingParams, operator: SmoothingOperator | None
) -> SmoothingOperator:
    if operator is None:
        return build_operator(geometry, params)
    if operator.key != operator_key(geometry, params):
        raise ParameterError(
            "the operator was built for another geometry or other build parameters "
            f"({', '.join(field_names(OperatorParams))})",
            field="operator",
        )
    return operator


def free_set(
    geometry: Geometry, op: SmoothingOperator, fix_boundary: bool, preserve_volume: bool,
    corners: NDArray[np.bool_] | None = None,
) -> tuple[NDArray[np.bool_], int]:
    """Points eliminated from the system: fixed ones (section 8), uncoupled ones and a track's
    held ``corners`` (:func:`held_corners`).

    Returns
    -------
    fixed : ndarray of bool, shape (n,)
        Given fixed points, the boundary with ``fix_boundary``, and points without any
        coupling in ``L`` (they pass through bit-identical).
    n_fixed : int
        Points fixed by the input or ``fix_boundary``.
    """
    nb = op.neighborhoods
    fixed = geometry.fixed_mask()
    if fix_boundary:  # no boundary on k-NN neighbourhoods (_boundary_ignored)
        fixed = fixed | nb.boundary
    if preserve_volume:
        check_preservable(geometry, fixed)
    L = op.L
    coupled = (np.diff(L.indptr) > 0) | (np.bincount(L.indices, minlength=geometry.n) > 0)
    pinned = op.pinned if op.pinned is not None else False  # open-curve ends (issue 21)
    held = False if corners is None else corners
    return fixed | ~coupled | pinned | held, int(fixed.sum())


def smoothing_system(
    geometry: Geometry,
    op: SmoothingOperator,
    fixed: NDArray[np.bool_],
    frame: Frame,
    params: SmoothingParams,
) -> tuple[SmoothingSystem, Callable[[Array], Array]]:
    """The system of the selected mode, in the internal frame (the mode dispatch point), and
    the map from its solution ``U`` to the free points.

    ``free`` displacement: eq. (4) with the fixed points eliminated
    (:func:`~service.core.system.elimination.laplacian_system`); ``normal``: one unknown per normal
    direction of each point (:func:`~service.core.system.displacement.normal_mode`).
    """
    P = frame.points(geometry.points)
    omega = geometry.omega() / frame.weight_scale
    if params.displacement == "normal":
        return normal_mode(geometry, op.L, op.neighborhoods, P, omega, fixed)
    return laplacian_system(op.L, P, omega, fixed), lambda U: U
