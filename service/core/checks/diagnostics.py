"""The report stage's numbers: input-frame values, the shape checks and warnings of
:mod:`.guards`, timings, work counters and the optional spectrum (eq. 12), as the fields of a
:class:`~service.core.result.SmoothResult` (the pipeline builds it, with the plan)."""

from __future__ import annotations

import time
from dataclasses import replace
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
from service.core.finish.outliers import beyond_noise
from service.core.frame import Frame
from service.core.geometry import Geometry
from service.core.noise.estimate import codimension, estimate_noise
from service.core.noise.robust import DataWeights, outlier_note
from service.core.operator.build import SmoothingOperator
from service.core.params import SmoothingParams
from service.core.run import Run
from service.core.search.target import Solution, Target

__all__ = ["diagnostics"]

Array = NDArray[np.float64]


def diagnostics(
    geometry: Geometry,
    params: SmoothingParams,
    op: SmoothingOperator,
    frame: Frame,
    run: Run,
    sol: Solution,
    fin: Finished,
    n_fixed: int,
    weights: DataWeights | None = None,
) -> dict[str, Any]:
    """The fields of the run's :class:`~service.core.result.SmoothResult`: input-frame numbers
    (eq. 15's ``phi``, lambda of eq. 4), timings and work counters.

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
    weights = _kept(weights, fin, run.notes)
    solved = X if fin.backoff is None else fin.backoff.undone(X)  # the smoothing's own moves
    weights = _measured(weights, geometry, solved, target.sigma, params.outliers, run.notes)
    checks, shape_warnings, sigma = _shape(
        geometry, params, target, X, _bulk_rms(dev_pt, weights), run.notes
    )
    timings = _timings(op, sol, run)
    tau = target.tau
    spectrum = None
    if params.spectrum:
        spectrum = _spectrum(op, geometry, frame, search.lam, n_fixed, run.notes)
    return dict(
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
        warnings=[*run.notes, *(stats.warnings if stats else [])],
        spectrum=spectrum,
        displacement=params.displacement,
        tau_rule=params.tau_rule,
        sigma_estimate=target.sigma if target.sigma is not None else sigma,
        tau_how=target.how,
        checks=checks.to_dict(),
        bound=sol.bound,
        shape_warnings=shape_warnings,
        noise_found=None if params.tau_rule != "auto" else bool(target.sigma),
        **_data_weights(weights, params.outliers),
        tangential=None if fin.tangential is None else fin.tangential.to_dict(frame.phi_factor),
        output_deviation=(
            None if dev is None else _output_deviation(geometry, moved, phi, fin, frame)
        ),
    )


def _kept(dw: DataWeights | None, fin: Finished, notes: list[str]) -> DataWeights | None:
    """The data weights with the outliers the finish stage kept in place (issue 31: a cloud's
    points the solve moved far are kept and flagged too), with a note when it added some."""
    kept = fin.outliers
    if dw is None or kept is None or kept.size <= dw.outliers.size:
        return dw
    notes.append(
        f"{kept.size - dw.outliers.size} more points the solve moved far from their "
        "input (beyond twice the outliers' threshold) were kept in place as outliers too"
    )
    return replace(dw, outliers=kept)


def _measured(
    dw: DataWeights | None,
    geometry: Geometry,
    X: Array,
    sigma: float | None,
    mode: str,
    notes: list[str],
) -> DataWeights | None:
    """The data weights with only the pulled-in outliers whose move is beyond what the noise
    and the smoothing explain (:func:`~service.core.finish.outliers.beyond_noise`, issue 31),
    and their note counting those (none: no note). The rest are the Gaussian tail of shape
    detail; the weights the residual test set stay (``data_weights`` still says ``robust``)."""
    if dw is None or mode != "pull" or dw.outliers.size == 0:
        return dw
    kept = beyond_noise(geometry.points, X, dw.outliers, sigma, codimension(geometry))
    if kept.size == dw.outliers.size:
        return dw
    note = outlier_note(int(dw.outliers.size), mode, dw.robust)
    if note in notes:
        at = notes.index(note)
        if kept.size:
            notes[at] = outlier_note(int(kept.size), mode, dw.robust)
        else:
            del notes[at]
    return replace(dw, outliers=kept, pulled=np.intersect1d(dw.pulled, kept))


def _bulk_rms(dev_pt: Array, dw: DataWeights | None) -> float:
    """The RMS move of the points that are not outliers: an outlier pulled in moves by its
    offset, which says nothing about whether the shape itself was smoothed (issue 31)."""
    if dw is None or dw.outliers.size == 0 or dw.outliers.size >= dev_pt.size:
        return float(np.sqrt(np.mean(dev_pt**2)))
    keep = np.ones(dev_pt.size, dtype=bool)
    keep[dw.outliers] = False
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
    notes: list[str],
) -> tuple[ShapeChecks, list[str], float | None]:
    """The shape checks of :mod:`.guards`, their warnings (added to ``notes``) and the noise
    level they compared with.

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
    notes.extend(shape_warnings)
    note = fold_note(checks, params.displacement)
    if note:
        notes.append(note)
    return checks, shape_warnings, sigma


def _timings(op: SmoothingOperator, sol: Solution, run: Run) -> dict[str, float]:
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
    timings["total"] = time.perf_counter() - run.t0
    return timings


def _data_weights(dw: DataWeights | None, mode: str) -> dict[str, Any]:
    """The outliers, what was done with them (issue 31) and the data weights of the run
    (issue 21), as
    :class:`~service.core.result.SmoothResult` fields."""
    if dw is None:
        return {}
    kinds = ([f"robust ({dw.robust})"] if dw.robust != "none" else []) + (
        ["noise"] if dw.uneven else []
    )
    return {
        "outliers": dw.outliers,
        "data_weights": " + ".join(kinds) or None,
        "omega": dw.omega if kinds else None,
        "pulled": dw.pulled,
        "outlier_mode": mode if dw.outliers.size else None,
    }


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
    notes: list[str],
) -> Spectrum | None:
    if n_fixed:
        notes.append("spectrum: not available with fixed points (eq. 12 assumes none)")
        return None
    if geometry.n > SPECTRUM_MAX_POINTS:
        notes.append(f"spectrum: only computed for inputs up to {SPECTRUM_MAX_POINTS} points")
        return None
    L = op.L * op.frame.scale ** (-op.frame.power)
    sigma, _ = singular_values(L, geometry.omega())
    return Spectrum(sigma=sigma, gamma=filter_factors(sigma, frame.lam_out(lam)))
