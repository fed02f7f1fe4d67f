"""The flat :class:`SmoothingParams`: the one definition the library, CLI, HTTP API and job queue
all use (its typed views per stage: :mod:`service.core.params.groups`)."""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator
from pydantic_core import PydanticCustomError

from service.core.params.groups import (
    BudgetParams,
    DataParams,
    FinishParams,
    OperatorParams,
    ScaleParams,
    view,
)
from service.core.params.names import (
    MAX_ITERATIONS,
    MAX_ITERATIONS_BOUND,
    MAX_K,
    REPORT_PRESET,
    SPECTRUM_MAX_POINTS,
    TOLERANCE,
    Boundary,
    Displacement,
    Ends,
    Junctions,
    LaplacianVariant,
    MethodName,
    NeighborhoodKind,
    NoiseWeights,
    OutlierMode,
    Preset,
    RobustRule,
    SearchName,
    SolverName,
    Tangential,
    TauRule,
    WeightScheme,
)

__all__ = ["SmoothingParams"]

class SmoothingParams(BaseModel):
    """Parameters of one smoothing run (report sections 2, 4, 6 and 8).

    At most one of ``lam``, ``tau`` and ``rms`` selects how the regularization parameter
    lambda of eq. (4) is obtained: given directly, or found so that the deviation
    ``phi(lambda) = ||D(X - P)||_F^2`` of eq. (15) equals ``tau`` (section 6.3), where
    ``rms`` stands for ``tau = sum_i omega_i^2 * rms^2``. With none of them (or
    ``tau="auto"``) tau is chosen from the estimated noise level (discrepancy principle);
    ``tau="gcv"`` chooses it by generalized cross-validation instead.

    ``preset="report"`` sets every field the caller does not give to the report's choice
    (:data:`REPORT_PRESET`), reproducing its method exactly.
    """

    model_config = ConfigDict(
        extra="forbid",
        json_schema_extra={
            "examples": [
                {},
                {"tau": 2e-4},
                {"tau": "gcv"},
                {"rms": 0.001, "laplacian": "feature", "sigma_f": 0.5},
                {"tau": 2e-4, "preset": "report"},
                {"lam": 0.05, "weights": "cotangent", "fix_boundary": True},
            ]
        },
    )

    lam: float | None = Field(
        default=None,
        gt=0,
        allow_inf_nan=False,
        description="Regularization parameter lambda of eq. (4), given directly (no search).",
        examples=[0.05],
    )
    tau: Annotated[float, Field(gt=0, allow_inf_nan=False)] | TauRule | None = Field(
        default=None,
        description=(
            "Smoothing factor tau of eq. (3): the budget for the weighted sum of squared "
            "displacements sum_i omega_i^2 ||x_i - p_i||^2. A number in (0, phi(0)); 'auto' "
            "(also when none of lam, tau, rms is given): from the estimated noise level; 'gcv': "
            "by generalized cross-validation."
        ),
        examples=[2e-4, "auto", "gcv"],
    )
    rms: float | None = Field(
        default=None,
        gt=0,
        allow_inf_nan=False,
        description="Target RMS displacement; equivalent to tau = sum_i omega_i^2 * rms^2.",
        examples=[0.001],
    )
    laplacian: LaplacianVariant = Field(
        default="normalized",
        description=(
            "Laplacian variant (section 4.1): normalized L(n), curvature-scaled L(kappa) "
            "(eq. 9) or feature-preserving L(f) (eq. 10)."
        ),
    )
    weights: WeightScheme = Field(
        default="uniform",
        description=(
            "Neighbour weights w_ij of eq. (1). 'auto': the report's choice, reciprocal "
            "distance for curves (section 4.2), mean value for meshes and Delaunay "
            "neighbourhoods (4.3-4.4), reciprocal distance for k-NN neighbourhoods. Default "
            "'uniform': weights computed from a noisy input move points along the shape "
            "(benchmarks/quality/README.md)."
        ),
    )
    neighborhood: NeighborhoodKind = Field(
        default="delaunay",
        description="Point clouds only: Delaunay neighbourhoods (section 4.4) or plain k-NN.",
    )
    k: int = Field(
        default=20,
        ge=3,
        le=MAX_K,
        description="Point clouds only: neighbours per point (the report: 12).",
    )
    sigma_h: float = Field(
        default=1e-7, gt=0, allow_inf_nan=False, description="Huber threshold of eq. (8)."
    )
    sigma_f: float = Field(
        default=0.5,
        gt=0,
        allow_inf_nan=False,
        description="Width of the Gaussian psi of eq. (10), on curvatures rescaled to [0, 1].",
    )
    robust: RobustRule = Field(
        default="auto",
        description=(
            "Robust data weights against outliers: each point's residual against the local fit "
            "of its neighbours, scaled by the noise, reduces its weight omega_i (Huber or "
            "Tukey), so tau is spent on the bulk noise and outliers are pulled in; the report "
            "lists them ('outliers'). 'auto': with the automatic tau and no given weights, only "
            "when more points lie beyond the Gaussian extreme than the noise explains; 'none': "
            "the report's plain weights."
        ),
    )
    noise_weights: NoiseWeights = Field(
        default="auto",
        description=(
            "Weights from a per-point noise estimate sigma_i: omega_i = (sigma/sigma_i)^(1/2) "
            "(the report's D = 1/sigma, FITPACK's w = 1/sigma, softened: measured better), "
            "the automatic tau counting the noise each point carries. 'auto': with the "
            "automatic tau and no given weights, when the noise level varies across the input; "
            "'local': always; 'none': never."
        ),
    )
    outliers: OutlierMode = Field(default="auto", description=(
        "Outliers found by the robust weights: 'flag' keeps them in place, flagged in the output "
        "(LAS class 7, PLY/PCD 'outlier'); 'drop' writes a cloud without them; 'pull' moves them "
        "into their ring (eq. 4, omega_i -> 0). 'auto': flag for clouds, pull otherwise."))
    tolerance: float = Field(
        default=TOLERANCE,
        gt=0,
        lt=1,
        description="Relative tolerance xi on |phi - tau| / tau (section 6.3).",
    )
    max_iterations: int = Field(
        default=MAX_ITERATIONS,
        ge=1,
        le=MAX_ITERATIONS_BOUND,
        description="Cap on lambda iterations of the tau search.",
    )
    fix_boundary: bool = Field(
        default=False,
        description="Fix mesh boundary vertices and open-polyline endpoints (infinite weights).",
    )
    preserve_volume: bool = Field(
        default=False,
        description=(
            "Rescale the result about its centroid to keep the enclosed volume (closed meshes) "
            "or area (closed planar polygons); report sections 8-9. The rescaling follows the "
            "lambda search, so the final deviation (rms/max_deviation) can exceed tau; phi is "
            "the deviation before rescaling."
        ),
    )
    # --- core-engine block (search, solver path, method, order) ----------------------------
    solver: SolverName = Field(
        default="auto",
        description="Linear solver: 'auto' (CHOLMOD when the factor fits the memory budget, "
        "else the matrix-free conjugate gradients), 'cholmod' (scikit-sparse; falls back to "
        "SciPy's SuperLU with a warning when unavailable), 'superlu', or 'cg' (matrix-free, "
        "O(n) memory).",
    )
    search: SearchName = Field(
        default="auto",
        description="lambda search for tau/rms: 'newton' (Lanczos estimate, then safeguarded "
        "Newton on phi^(-1/2k) reusing one factorization), 'rational' (the report's rational "
        "interpolation, section 6.3), 'auto' (newton).",
    )
    method: MethodName = Field(
        default="tikhonov",
        description="'tikhonov': eq. (4) (with `order`); 'windowed-sinc': a polynomial low-pass "
        "filter of the same Laplacian whose pass band is chosen so that phi = tau (no "
        "factorization).",
    )
    order: int = Field(
        default=2,
        ge=1,
        le=8,
        description="Iterated Tikhonov order k: filter 1 - (mu/(mu+lambda))^k, k solves per "
        "lambda with one factorization (1 = the report's eq. 4; default 2, chosen by the "
        "quality benchmark).",
    )
    # --- end core-engine block ------------------------------------------------------------
    spectrum: bool = Field(
        default=False,
        description="Also return the singular values of L and the filter factors of eq. (12) "
        f"(inputs up to {SPECTRUM_MAX_POINTS} points).",
    )

    # --- core-quality: displacement, max-norm bound, preset --------------------------------------
    displacement: Displacement = Field(
        default="auto",
        description=(
            "'free': every coordinate of every point may move (eq. 4). 'normal': each point "
            "moves along its normal only, x_i = p_i + t_i n_i, normals from the input's "
            "neighbourhoods (surfaces and point clouds; the normal plane for curves in 3-D), "
            "the smoothness measured across the shape. 'auto': the one the quality benchmark "
            "found best for the kind of input (normal for meshes and point clouds, free for "
            "curves)."
        ),
    )
    tangential: Tangential = Field(
        default="auto",
        description=(
            "Meshes smoothed by normal displacement: 'auto' also removes the noise along the "
            "surface, by as much as the data show (the tangential share of the input's "
            "Laplacian; nothing moves when the noise is along the normals), without folding "
            "faces; 'off': normal displacement only. An explicit displacement 'normal' "
            "implies 'off'."
        ),
    )
    presmooth: int = Field(
        default=2,
        ge=0,
        le=100,
        description=(
            "Averaging steps x <- (x + mean of neighbours) / 2 applied to a copy of the input "
            "before the curvature and the row scales of L(kappa) / L(f) (eqs. 7-10) are "
            "computed, so that they follow the shape rather than the noise; 0 computes them "
            "from the input itself (the report)."
        ),
    )
    junctions: Junctions = Field(
        default="corner",
        description=(
            "Curve networks: a vertex where three or more curves meet is a 'corner' (no "
            "smoothness term of its own: each curve is smoothed up to it) or is smoothed like "
            "any other vertex, towards the centroid of its neighbours ('smooth', the report)."
        ),
    )
    ends: Ends = Field(
        default="auto",
        description=(
            "Open polylines: an endpoint keeps the report's row, which pulls it towards its one "
            "neighbour so that the curve contracts along itself ('pulled'), or stays in place "
            "while the curve up to it is smoothed ('fixed', as VTK's windowed-sinc does; "
            "'auto')."
        ),
    )
    boundary: Boundary = Field(
        default="auto",
        description=(
            "Open meshes: a boundary vertex's row of L averages its one-sided 1-ring ('ring', "
            "the report; it pulls the border inwards) or its neighbours along the boundary "
            "only ('curve', VTK's boundary smoothing). 'auto': 'curve' with free "
            "displacement, 'ring' with normal displacement."
        ),
    )
    max_deviation: float | None = Field(
        default=None,
        gt=0,
        allow_inf_nan=False,
        description=(
            "Max-norm bound: no point moves further than this, ||x_i - p_i|| <= max_deviation "
            "for every i (report section 9), alone or together with tau/rms/lam."
        ),
    )
    strict: bool = Field(
        default=False,
        description=(
            "Fail instead of warning when the result lost shape (faces folded where the input "
            "had none; volume, area or length changed beyond what removing the noise "
            "explains): a typed error 'shape-lost' (CLI exit 12, HTTP 422), nothing written. "
            "For pipelines that must never pass a damaged file on."
        ),
    )
    # --- tiles (issue 23) ---------------------------------------------------------------------
    tile_points: int | None = Field(
        default=None,
        ge=1000,
        description=(
            "Smooth in spatial tiles of about this many points, each with a halo as wide as the "
            "solution's influence reaches, under one global tau (service/core/tiles); also "
            "chosen automatically for jobs whose memory estimate exceeds the limit. Not with "
            "preserve_volume, max_deviation, spectrum, tau='gcv', windowed-sinc or L(f)."
        ),
    )
    preset: Preset | None = Field(
        default=None,
        description=(
            "'report': every field not given takes the choice of report TW 451 (L(n), "
            "mean-value/reciprocal weights, Delaunay k = 12, free displacement, first order, "
            "rational lambda search), reproducing its method exactly."
        ),
    )

    @field_validator("tau", mode="before")
    @classmethod
    def _tau_number_or_rule(cls, value: Any) -> Any:
        """A positive finite number, or one of the rules (one error located at ``tau``)."""
        if value is None or value in ("auto", "gcv"):
            return value
        try:
            number = float(value)
        except (TypeError, ValueError):
            raise PydanticCustomError(
                "tau_type", "Input should be a number greater than 0, 'auto' or 'gcv'"
            ) from None
        if isinstance(value, bool) or not math.isfinite(number):
            raise PydanticCustomError("finite_number", "Input should be a finite number")
        if number <= 0:
            raise PydanticCustomError(
                "greater_than", "Input should be greater than 0", {"gt": 0}
            )
        return number

    @field_validator("*", mode="before")
    @classmethod
    def _booleans_are_not_numbers(cls, value: Any, info: Any) -> Any:
        """``true`` is not ``1`` and ``0`` is not ``false`` (pydantic's lax mode takes both)."""
        field = cls.model_fields.get(info.field_name)
        if field is None:
            return value
        if field.annotation is bool and not isinstance(value, bool):
            raise PydanticCustomError("bool_type", "Input should be a valid boolean")
        if isinstance(value, bool) and field.annotation is not bool:
            raise PydanticCustomError("bool_not_number", "Input should be a number, not a boolean")
        return value

    @model_validator(mode="before")
    @classmethod
    def _apply_preset(cls, data: Any) -> Any:
        if isinstance(data, dict) and data.get("preset") == "report":
            data = {**REPORT_PRESET, **data}
        return data

    @model_validator(mode="after")
    def _at_most_one_target(self) -> SmoothingParams:
        given = [name for name in ("lam", "tau", "rms") if getattr(self, name) is not None]
        if len(given) > 1:
            raise ValueError(f"give at most one of lam, tau or rms (got {', '.join(given)})")
        return self

    @property
    def tau_rule(self) -> Literal["lam", "tau", "rms", "auto", "gcv"]:
        """How lambda is chosen: given, from tau or rms, or automatically (auto, gcv)."""
        if self.lam is not None:
            return "lam"
        if self.rms is not None:
            return "rms"
        if isinstance(self.tau, float):
            return "tau"
        return "gcv" if self.tau == "gcv" else "auto"

    @property
    def operator(self) -> OperatorParams:
        """The operator group (what the Laplacian depends on; the operator cache's key)."""
        return view(self, OperatorParams)

    @property
    def budget(self) -> BudgetParams:
        """The budget group: target, lambda search, solver path, order, max-norm bound."""
        return view(self, BudgetParams)

    @property
    def data(self) -> DataParams:
        """The data-weights group (robust and per-point noise weights)."""
        return view(self, DataParams)

    @property
    def finish(self) -> FinishParams:
        """The finishing group (tangential step, volume, clipping, checks, spectrum)."""
        return view(self, FinishParams)

    @property
    def scale(self) -> ScaleParams:
        """The scale group (tiles, fixed boundary, displacement mode)."""
        return view(self, ScaleParams)
