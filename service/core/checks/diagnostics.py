"""The report stage's numbers: input-frame values, the shape checks and warnings of
:mod:`.guards`, timings, work counters and the optional spectrum (eq. 12), as the fields of a
:class:`~service.core.result.SmoothResult` (the pipeline builds it, with the plan)."""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from numpy.typing import NDArray

from service.core.checks.guards import (
    ShapeChecks,
    fold_note,
    guard_warnings,
    renoised_measure,
    shape_checks,
)
from service.core.checks.spectrum import (
    SPECTRUM_MAX_POINTS,
    Spectrum,
    filter_factors,
    singular_values,
)
from service.core.errors import ShapeLost, SolverError
from service.core.finish.finished import Finished
from service.core.finish.outliers import Outliers
from service.core.frame import Frame
from service.core.geometry import Geometry
from service.core.noise.estimate import codimension, estimate_noise
from service.core.noise.robust import DataWeights
from service.core.operator.build import SmoothingOperator
from service.core.params import SmoothingParams
from service.core.search.target import Solution, Target
from service.core.warnings import EngineWarning, warning

__all__ = ["diagnostics"]

Array = NDArray[np.float64]


def diagnostics(
    geometry: Geometry,
    params: SmoothingParams,
    op: SmoothingOperator,
    frame: Frame,
    t0: float,
    sol: Solution,
    fin: Finished,
    n_fixed: int,
    weights: DataWeights | None = None,
) -> tuple[dict[str, Any], list[EngineWarning]]:
    """The fields of the run's :class:`~service.core.result.SmoothResult`: input-frame numbers
    (eq. 15's ``phi``, lambda of eq. 4), timings (from ``t0``), work counters and the finish
    stage's outliers (``fin.outliers``); and the checks' warnings (shape, folds, spectrum).

    Raises
    ------
    SolverError
        A non-finite lambda, phi or point.
    ShapeLost
        ``params.strict`` and a shape warning.
    """
    X, dev, search, target = fin.X, sol.dev, sol.search, sol.target
    moved = X - geometry.points
    dev_pt = np.linalg.norm(moved, axis=1)
    # phi of the solution (before any volume rescaling), as recorded in the history
    phi = frame.phi_out(search.phi) if dev is not None else 0.0
    if not (np.isfinite(phi) and np.isfinite(search.lam) and np.isfinite(X).all()):
        raise SolverError(  # never report a non-finite number (issue 15)
            "the solution is not finite at this scale (lambda, phi or the points overflowed)",
            field="params",
        )
    stats = dev.stats if dev is not None else None
    rms = float(np.sqrt(np.mean(dev_pt**2)))
    outliers = None if fin.outliers is None else fin.outliers.indices
    checks, shape_warnings, sigma, said = _shape(
        geometry, params, target, X, _bulk_rms(dev_pt, outliers)
    )
    timings = _timings(op, sol, t0)
    tau = target.tau
    spectrum = None
    if params.spectrum:
        spectrum, unavailable = _spectrum(op, geometry, frame, search.lam, n_fixed)
        said += unavailable
    fields = dict(
        points=X,
        lam=params.lam if params.lam is not None else frame.lam_out(search.lam),
        phi=phi,
        tau=tau,
        relative_error=None if tau is None else abs(phi - tau) / tau,
        converged=search.converged,
        iterations=len(search.history),
        factorizations=stats.factorizations if stats else 0,
        solves=stats.solves if stats else 0,
        matvecs=stats.matvecs if stats else 0,
        history=[(frame.lam_out(lam), frame.phi_out(p)) for lam, p in search.history],
        deviation=dev_pt,
        rms_displacement=rms,
        max_displacement=float(dev_pt.max()),
        timings=timings,
        solver=dev.solver.name if dev is not None and params.method == "tikhonov" else "none",
        method=params.method,
        search="none" if params.lam is not None else params.search,
        order=params.order,
        laplacian=params.laplacian,
        weights=op.scheme,
        kind=geometry.kind,
        n_fixed=n_fixed,
        volume_scale=fin.volume_scale,
        spectrum=spectrum,
        displacement=params.displacement,
        tau_rule=params.tau_rule,
        sigma_estimate=target.sigma if target.sigma is not None else sigma,
        tau_how=target.how,
        checks=checks.to_dict(),
        bound=sol.bound,
        shape_warnings=shape_warnings,
        noise_found=None if params.tau_rule != "auto" else bool(target.sigma),
        tangential=None if fin.tangential is None else fin.tangential.to_dict(frame.phi_factor),
        output_deviation=(
            None if dev is None else _output_deviation(geometry, moved, phi, fin, frame)
        ),
        **_data_weights(weights, fin.outliers),
    )
    return fields, said


def _data_weights(dw: DataWeights | None, outliers: Outliers | None) -> dict[str, Any]:
    """The data weights of the run (issue 21) and the outliers as the finish stage left them
    (issue 31; one record, :class:`~service.core.finish.outliers.Outliers`), as
    :class:`~service.core.result.SmoothResult` fields."""
    if dw is None or outliers is None:
        return {}
    kinds = ([f"robust ({dw.robust})"] if dw.robust != "none" else []) + (
        ["noise"] if dw.uneven else []
    )
    return {
        "outliers": outliers.indices,
        "data_weights": " + ".join(kinds) or None,
        "omega": dw.omega if kinds else None,
        "pulled": outliers.pulled,
        "outlier_mode": outliers.mode if outliers.count else None,
    }


def _bulk_rms(dev_pt: Array, outliers: NDArray[np.int64] | None) -> float:
    """The RMS move of the points that are not outliers: an outlier pulled in moves by its
    offset, which says nothing about whether the shape itself was smoothed (issue 31)."""
    if outliers is None or outliers.size == 0 or outliers.size >= dev_pt.size:
        return float(np.sqrt(np.mean(dev_pt**2)))
    keep = np.ones(dev_pt.size, dtype=bool)
    keep[outliers] = False
    return float(np.sqrt(np.mean(dev_pt[keep] ** 2)))


def _output_deviation(
    geometry: Geometry, moved: Array, phi: float, fin: Finished, frame: Frame
) -> dict[str, float]:
    """What the output is (issue 30): its own deviation ``||D (X - P)||_F^2`` (input frame, the
    run's weights ``omega``) first, then its parts: the Tikhonov solve's ``phi`` at the
    reported lambda (eq. 15), the tangential step's ``psi`` (moves orthogonal to the normal
    solve's, so the two add), and the rest (outliers placed by eq. 4 without their data weight,
    volume rescaling, clipping)."""
    w2 = geometry.omega() ** 2
    total = float(np.sum(w2 * np.einsum("ij,ij->i", moved, moved)))
    psi = 0.0 if fin.tangential is None else float(fin.tangential.psi * frame.phi_factor)
    return {"total": total, "tikhonov": phi, "tangential": psi, "other": total - phi - psi}


def _shape(
    geometry: Geometry,
    params: SmoothingParams,
    target: Target,
    X: Array,
    rms: float,
) -> tuple[ShapeChecks, list[str], float | None, list[EngineWarning]]:
    """The shape checks of :mod:`.guards`, their messages, the noise level they compared with
    and the warnings (the shape checks' and the folds kept).

    Raises
    ------
    ShapeLost
        ``params.strict`` and a shape warning.
    """
    checks = shape_checks(geometry, X)
    sigma = _noise_for_checks(geometry, params, target, rms)
    back = lambda: renoised_measure(geometry, X, sigma)  # noqa: E731 (only called when needed)
    moves = rms / (sigma * np.sqrt(max(codimension(geometry), 1))) if sigma else None
    shape_warnings = guard_warnings(checks, params.tau_rule, back, moves)
    if shape_warnings and params.strict:
        raise ShapeLost(shape_warnings, checks.to_dict())
    numbers = {"moves": moves, "new_folds": checks.new_folds,
               "area_change": checks.area_change}  # fmt: skip
    said = [warning("shape", message, **numbers) for message in shape_warnings]
    note = fold_note(checks, params.displacement)
    if note:
        said.append(warning("folds-kept", note, folded=checks.folded_faces,
                            folded_input=checks.folded_input))  # fmt: skip
    return checks, shape_warnings, sigma, said


def _timings(op: SmoothingOperator, sol: Solution, t0: float) -> dict[str, float]:
    """Seconds per stage: build, analysis, factorization, solve, products, search, total."""
    timings = dict(op.timings)
    stats = sol.dev.stats if sol.dev is not None else None
    if stats is not None:
        timings.update(
            analysis=stats.analysis,
            factorization=stats.factorization,
            solve=stats.solve,
            matvec=stats.matvec,
        )
    timings["search"] = sol.seconds
    timings["total"] = time.perf_counter() - t0
    return timings


def _noise_for_checks(
    geometry: Geometry, params: SmoothingParams, target: Target, rms: float
) -> float | None:
    """The noise level the shape checks compare with: the automatic tau's estimate, else one
    made here (sampled, bounded cost) when anything moved; ``None`` when no noise is found."""
    if params.tau_rule == "auto":
        return target.sigma or None
    if rms == 0 or geometry.dim - 1 < 1:
        return None
    est = estimate_noise(geometry)
    return est.sigma if est is not None and est.sigma > 0 else None


def _spectrum(
    op: SmoothingOperator,
    geometry: Geometry,
    frame: Frame,
    lam: float,
    n_fixed: int,
) -> tuple[Spectrum | None, list[EngineWarning]]:
    """Singular values and filter factors (eq. 12), or why not."""
    if n_fixed:
        return None, [warning("spectrum-unavailable",
                              "spectrum: not available with fixed points (eq. 12 assumes none)")]
    if geometry.n > SPECTRUM_MAX_POINTS:
        return None, [warning(
            "spectrum-unavailable",
            f"spectrum: only computed for inputs up to {SPECTRUM_MAX_POINTS} points",
            points=geometry.n, bound=SPECTRUM_MAX_POINTS,
        )]  # fmt: skip
    L = op.L * op.frame.scale ** (-op.frame.power)
    sigma, _ = singular_values(L, geometry.omega())
    return Spectrum(sigma=sigma, gamma=filter_factors(sigma, frame.lam_out(lam))), []
