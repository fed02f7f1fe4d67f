"""The result record of one smoothing run."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from service.core.checks.spectrum import Spectrum
from service.core.warnings import EngineWarning, to_wire

if TYPE_CHECKING:  # pragma: no cover
    from service.core.plan import Plan

__all__ = ["PointCounts", "SmoothResult", "Spectrum"]


@dataclass(frozen=True)
class PointCounts:
    """What the file holds against what was solved (issue 38: a welded PLY reported the 1722
    points solved while its file and output hold 5096 vertices).

    Attributes
    ----------
    points_in : int
        Vertices (points) in the input as read, before welding.
    points_solved : int
        Points the engine smoothed (after welding coincident vertices).
    points_out : int
        Vertices written (the input's count; less the outliers ``drop`` leaves out).
    welded_pairs : int
        Vertices welded onto a coincident one (``points_in - points_solved``).
    """

    points_in: int
    points_solved: int
    points_out: int
    welded_pairs: int = 0

    def to_dict(self) -> dict[str, int]:
        return {"points_in": self.points_in, "points_solved": self.points_solved,
                "points_out": self.points_out, "welded_pairs": self.welded_pairs}  # fmt: skip


@dataclass(frozen=True)
class SmoothResult:
    """Smoothed points plus convergence diagnostics.

    Attributes
    ----------
    points : ndarray, shape (n, s)
        Smoothed points ``X``, same order and count as the input; fixed points bit-identical.
    lam : float
        The lambda of eq. (4) used for ``points``.
    phi : float
        ``phi(lam) = ||D(X - P)||_F^2`` (eq. 15).
    tau : float or None
        Requested smoothing factor (``None`` when ``lam`` was given).
    relative_error : float or None
        ``|phi - tau| / tau``.
    converged : bool
        Whether ``relative_error <= tolerance`` (always true for a given ``lam``).
    iterations : int
        lambda values tried (each one a numeric factorization and a solve).
    factorizations : int
        Numeric factorizations done.
    solves, matvecs : int
        Solves with a factorization (each for all coordinate columns) and products with
        ``L^T L`` (Lanczos, conjugate gradients, residual checks).
    history : list of (float, float)
        ``(lambda, phi)`` for every lambda tried, in order.
    deviation : ndarray, shape (n,)
        ``||x_i - p_i||`` per point.
    rms_displacement, max_displacement : float
        RMS and maximum of ``deviation``: measurements (``max_deviation`` of the parameters
        is the bound; the old names ``rms_deviation``/``max_deviation`` remain as read-only
        aliases).
    timings : dict
        Seconds per stage: neighborhoods, laplacian, analysis, factorization, solve, total.
    solver : str
        ``"cholmod"``, ``"superlu"`` or ``"cg"`` (matrix-free).
    search : str
        lambda search used: ``"auto"``, ``"newton"``, ``"rational"`` or ``"none"``.
    method : str
        ``"tikhonov"`` or ``"windowed-sinc"`` (then ``lam`` is the pass band's edge on the
        same scale, and ``solver`` is ``"none"``).
    order : int
        Iterated Tikhonov order.
    laplacian, weights : str
        Variant and resolved weight scheme actually used.
    kind : str
        ``"mesh"``, ``"curve"`` or ``"cloud"``.
    n_fixed : int
        Points held fixed.
    volume_scale : float or None
        Scale applied for volume/area preservation.
    warnings : list of EngineWarning
        Anything the user should know (solver fallback, search not converged, ...), in run
        order: typed records (code, message, numbers; :mod:`service.core.warnings`).
    spectrum : Spectrum or None
        Present when requested and the input is small enough.
    displacement : str
        ``"free"`` or ``"normal"`` (core-quality).
    tau_rule : str
        How lambda was set: ``"lam"``, ``"tau"``, ``"rms"``, ``"auto"`` or ``"gcv"``.
    sigma_estimate : float or None
        Estimated noise level (``service.core.noise.estimate``): the automatic tau's (0 when no
        noise was found), or for a given tau/rms/lam the one the shape checks compared with
        (``None`` when no noise was found).
    tau_how : str or None
        How the automatic tau was chosen, in words.
    checks : dict
        Guard-rail measurements (``service.core.checks.guards``): ``flipped_faces``,
        ``volume_change``, ``area_change``, ``moved_far``.
    bound : dict or None
        ``max_deviation`` bound: ``{"max_deviation", "rounds", "clipped"}``.
    shape_warnings : list of str
        The warnings of the shape checks alone (also in ``warnings``); ``strict=True`` fails
        on any.
    noise_found : bool or None
        Automatic tau: whether the noise estimate found noise (``False``: the input was
        returned unchanged, ``tau_how`` says why); ``None`` for other rules.
    tangential : dict or None
        The tangential step of normal displacement on meshes
        (:mod:`service.core.finish.tangential`): ``share`` (estimated along-surface over normal
        noise), ``budget`` and ``psi`` (its target and the tangential deviation reached, input
        frame), ``reverted`` (points kept at the normal solve's position to avoid folds);
        ``None`` when the step does not apply.
    output_deviation : dict or None
        The output's own deviation ``total = ||D (X - P)||_F^2`` (input frame, the run's
        weights), then its parts: ``tikhonov`` (``phi`` of the Tikhonov solve at the reported
        lambda), ``tangential`` (the tangential step's ``psi``) and ``other`` (outliers placed
        without their data weight, volume rescaling, clipping); ``None`` when nothing was
        solved. With a given tau the output's total is the Tikhonov ``phi``.
    tiles : dict or None
        Tiled runs: count, halo, rounds and every tile (points, halo, worker, seconds, phi).
    outliers : ndarray of int
        Points the robust data weights treated as outliers (``params.robust``; issue 21).
    omega : ndarray or None, shape (n,)
        The weights ``omega_i`` of the data term the run used when data weights were applied
        (the user's times the robust and noise weights): ``phi`` is ``sum omega_i^2
        ||x_i - p_i||^2`` with these over the points not in ``pulled``. ``None``: the user's.
    outlier_mode : str or None
        ``"flag"``, ``"drop"`` or ``"pull"``: what was done with the outliers (issue 31);
        ``None`` without outliers.
    pulled : ndarray of int
        Outliers with (next to) no weight, placed after the solve by ``argmin ||L X||^2`` over
        them (eq. 4 as ``omega_i -> 0``); their displacement is not part of ``phi``.
    data_weights : str or None
        Which data weights beyond the user's were applied: ``"robust (<rule>)"``, ``"noise"``
        (``1/sigma_i``, uneven noise), both joined by ``" + "``, or ``None``.
    unchanged : str or None
        Nothing smoothed, the output written by :mod:`service.workflows.smooth_file`:
        ``"copied"`` (the input's bytes) or ``"converted"`` (a straight conversion).
    counts : PointCounts or None
        Points in, solved, out and welded, set by the file workflows
        (:mod:`service.workflows.smooth_file`); ``None``: the points given are the points
        solved and returned (:attr:`point_counts`).
    """

    points: NDArray[np.float64]
    lam: float
    phi: float
    tau: float | None
    relative_error: float | None
    converged: bool
    iterations: int
    factorizations: int
    history: list[tuple[float, float]]
    deviation: NDArray[np.float64]
    rms_displacement: float
    max_displacement: float
    timings: dict[str, float]
    solver: str
    laplacian: str
    weights: str
    kind: str
    solves: int = 0
    matvecs: int = 0
    search: str = "none"
    method: str = "tikhonov"
    order: int = 1
    n_fixed: int = 0
    volume_scale: float | None = None
    warnings: list[EngineWarning] = field(default_factory=list)
    spectrum: Spectrum | None = None
    # --- core-quality block ---
    displacement: str = "free"
    tau_rule: str = "tau"
    sigma_estimate: float | None = None
    tau_how: str | None = None
    checks: dict[str, Any] = field(
        default_factory=lambda: dict.fromkeys(
            ("flipped_faces", "volume_change", "area_change", "moved_far")
        )
    )
    bound: dict[str, Any] | None = None
    shape_warnings: list[str] = field(default_factory=list)
    noise_found: bool | None = None
    tiles: dict[str, Any] | None = None  # tiled runs (service.core.tiles)
    # --- issue 21: robust and noise data weights ---
    outliers: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    data_weights: str | None = None
    omega: NDArray[np.float64] | None = None
    pulled: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    outlier_mode: str | None = None  # issue 31: "flag", "drop" or "pull" when there are outliers
    tangential: dict[str, Any] | None = None  # issue 21: the tangential step
    output_deviation: dict[str, float] | None = None  # issue 30: what the output is
    plan: Plan | None = None  # issue 29: every automatic choice and its evidence
    unchanged: str | None = None  # issue 32: set by service.workflows.smooth_file
    counts: PointCounts | None = None  # issue 38: set by service.workflows.smooth_file

    @property
    def point_counts(self) -> PointCounts:
        """:attr:`counts`, or the points given solved and returned."""
        n = self.n_points
        return self.counts if self.counts is not None else PointCounts(n, n, n, 0)

    @property
    def rms_deviation(self) -> float:
        """Deprecated name of :attr:`rms_displacement`."""
        return self.rms_displacement

    @property
    def max_deviation(self) -> float:
        """Deprecated name of :attr:`max_displacement` (``params.max_deviation`` is a bound)."""
        return self.max_displacement

    @property
    def n_points(self) -> int:
        return int(self.points.shape[0])

    @property
    def dimension(self) -> int:
        return int(self.points.shape[1])

    def report(self) -> dict[str, Any]:
        """JSON-ready diagnostics (the CLI's ``--report`` file and the API's report)."""
        out: dict[str, Any] = {
            "lambda": self.lam,
            "phi": self.phi,
            "tau": self.tau,
            "relative_error": self.relative_error,
            "converged": self.converged,
            "iterations": self.iterations,
            "factorizations": self.factorizations,
            "solves": self.solves,
            "matvecs": self.matvecs,
            "history": [{"lambda": lam, "phi": phi} for lam, phi in self.history],
            "n_points": self.n_points,
            **self.point_counts.to_dict(),
            "dimension": self.dimension,
            "kind": self.kind,
            "laplacian": self.laplacian,
            "weights": self.weights,
            "n_fixed": self.n_fixed,
            "rms_displacement": self.rms_displacement,
            "max_displacement": self.max_displacement,
            "volume_scale": self.volume_scale,
            "timings": dict(self.timings),
            "solver": self.solver,
            "search": self.search,
            "method": self.method,
            "order": self.order,
            **to_wire(self.warnings),
        }
        out.update(
            displacement=self.displacement,
            tau_rule=self.tau_rule,
            sigma_estimate=self.sigma_estimate,
            tau_how=self.tau_how,
            noise_found=self.noise_found,
            shape_warnings=list(self.shape_warnings),
            bound=self.bound,
            tangential=self.tangential,
            output_deviation=self.output_deviation,
            **self.checks,
        )
        out.update(
            outlier_count=int(self.outliers.size),
            outliers=[int(i) for i in self.outliers],
            outlier_mode=self.outlier_mode,
            data_weights=self.data_weights,
            plan=None if self.plan is None else self.plan.to_dict(),
            unchanged=self.unchanged,
        )
        if self.spectrum is not None:
            out["spectrum"] = self.spectrum.to_dict()
        if self.tiles is not None:
            out["tiles"] = self.tiles
        return out
