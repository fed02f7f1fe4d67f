"""The smoothing factor checked at submit: ``tau`` (or ``rms``) inside ``(0, phi(0))``.

``phi(0)`` (report eq. 14) is the deviation of the fully smoothed shape: every connected part
collapsed onto its weighted centroid, fixed points acting as boundary values. The engine
computes it exactly from the Laplacian (:func:`service.core.info.valid_range`), which for a point
cloud means building its neighbourhoods, the costliest stage of a run. So at submit:

* meshes, curves and clouds of at most ``exact_max_points`` points get the exact check;
* larger clouds without fixed points get the closed-form bound ``sum_i omega_i^2 ||p_i - p_w||^2``
  about the weighted centroid ``p_w`` (one part; several parts only lower ``phi(0)``), which
  catches every ``tau`` above it at once; a ``tau`` between the exact value and that bound
  (only possible for a cloud in separate clusters) is found when the job runs;
* where the exact ``phi(0)`` needs a factorization that does not fit (normal displacement on
  dense k-NN neighbourhoods), only ``tau > 0`` is checked here and the range when the job runs.

For normal displacement the centroid bound is not a proven bound of that mode's ``phi(0)``
(measured below it on spheres, helices and planes: 614 vs 643, 0.21 vs 2096); a ``tau`` above
it would collapse the shape onto its centroid anyway.
"""

from __future__ import annotations

import numpy as np

from service.core.errors import SolverError, TauOutOfRange
from service.core.frame import Frame
from service.core.geometry import Geometry
from service.core.params import SmoothingParams
from service.core.search.budget import free_weight, rms_to_tau, tau_to_rms

__all__ = ["centroid_bound", "check_tau"]


def centroid_bound(geometry: Geometry) -> tuple[float, float]:
    """``(sum omega^2 ||p - p_w||^2, sum omega^2)``: ``phi(0)`` of one part, and the weights."""
    w2 = geometry.omega() ** 2
    total = float(np.sum(w2))
    P = geometry.points
    scale = float(np.max(np.abs(P))) or 1.0  # scaled: no overflow for coordinates near 1e300
    Q = P / scale
    centre = (w2 @ Q) / total
    return float(np.sum(w2[:, None] * (Q - centre) ** 2)) * scale**2, total


def _range(geometry: Geometry, params: SmoothingParams, exact: bool) -> tuple[float, float]:
    """``(phi0, sum omega^2 over the points that can move)``."""
    if exact:
        from service.core.info import valid_range

        try:
            return valid_range(geometry, params)
        except SolverError:  # phi(0) needs a factorization that does not fit: the run checks
            return float("inf"), free_weight(geometry)
    return centroid_bound(geometry)


def _numeric(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def check_tau(
    geometry: Geometry,
    params: SmoothingParams,
    exact_max_points: int,
    *,
    analyse: bool = True,
    exact: bool | None = None,
) -> None:
    """Raise :class:`TauOutOfRange` when ``tau``/``rms`` cannot be met (see module docstring).

    ``analyse=False`` (``POST /v1/smooth``, where the engine checks the range itself) only
    checks that ``rms`` resolves to a positive, finite ``tau`` (``rms = 5e-324`` underflows).
    Non-numeric targets (an automatic ``tau``) have no range to check. ``exact=False``: no
    operator is built whatever the kind (an input too large for the caller to afford it): the
    centroid bound, or with fixed points only ``tau > 0`` (the run checks the range).
    """
    if not (_numeric(params.tau) or _numeric(params.rms)):
        return
    # the engine's own limits on extents and weights first (typed errors, never an overflow)
    omega = geometry.omega()
    Frame.of(geometry.points, params.laplacian).weighted(omega[omega < np.inf])
    if not analyse:
        if _numeric(params.rms):
            _, weight = centroid_bound(geometry)
            tau = rms_to_tau(params.rms, weight)  # type: ignore[arg-type]
            if not (0.0 < tau < float("inf")):
                raise TauOutOfRange(
                    f"rms={params.rms:.6g} gives the smoothing factor tau={tau:.6g}, which is not "
                    "a positive finite number",
                    field="params.rms",
                    tau=tau,
                    tau_max=float("nan"),
                )
        return
    fixed = geometry.fixed is not None or params.fix_boundary
    if exact is None:
        exact = geometry.kind != "cloud" or geometry.n <= exact_max_points or fixed
    if not exact and fixed:  # the centroid bound holds without boundary values only
        phi0, weight = float("inf"), free_weight(geometry)
    else:
        phi0, weight = _range(geometry, params, exact)
    if params.tau is not None:
        value, bound, name, tau = float(params.tau), phi0, "tau", float(params.tau)
    else:  # rms: the same budget per point (service.core.search.budget)
        value, name = float(params.rms), "rms"  # type: ignore[arg-type]
        bound, tau = tau_to_rms(phi0, weight), rms_to_tau(value, weight)
    if 0.0 < value < bound and 0.0 < tau < float("inf"):
        return
    kind = "phi(0)" if exact else "an upper bound of phi(0)"
    raise TauOutOfRange(
        f"smoothing factor {name}={value:.6g} is out of range: it must lie in (0, {bound:.6g}) "
        f"for this input, where the upper bound comes from {kind} = {phi0:.6g}, the deviation "
        "of the fully smoothed shape (valid_range is in tau units)",
        field=f"params.{name}",
        tau=tau,
        tau_max=phi0,
    )
