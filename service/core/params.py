"""Smoothing parameters: the one definition the library, CLI, HTTP API and job queue all use."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

__all__ = [
    "LaplacianVariant",
    "MethodName",
    "NeighborhoodKind",
    "SearchName",
    "SmoothingParams",
    "SolverName",
    "WeightScheme",
]

LaplacianVariant = Literal["normalized", "curvature", "feature"]
WeightScheme = Literal["auto", "uniform", "reciprocal", "mean-value", "cotangent"]
NeighborhoodKind = Literal["knn", "delaunay"]
# --- core-engine block (search, solver path, method, order) --------------------------------
SolverName = Literal["auto", "cholmod", "superlu", "cg"]
SearchName = Literal["auto", "newton", "rational"]
MethodName = Literal["tikhonov", "windowed-sinc"]
# --- end core-engine block --------------------------------------------------------------------


class SmoothingParams(BaseModel):
    """Parameters of one smoothing run (report sections 2, 4, 6 and 8).

    Exactly one of ``lam``, ``tau`` and ``rms`` selects how the regularization parameter
    lambda of eq. (4) is obtained: given directly, or found so that the deviation
    ``phi(lambda) = ||D(X - P)||_F^2`` of eq. (15) equals ``tau`` (section 6.3), where
    ``rms`` stands for ``tau = sum_i omega_i^2 * rms^2``.
    """

    model_config = ConfigDict(
        extra="forbid",
        json_schema_extra={
            "examples": [
                {"tau": 0.5},
                {"rms": 0.001, "laplacian": "feature", "sigma_f": 0.5},
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
    tau: float | None = Field(
        default=None,
        gt=0,
        allow_inf_nan=False,
        description=(
            "Smoothing factor tau of eq. (3): the budget for the weighted sum of squared "
            "displacements sum_i omega_i^2 ||x_i - p_i||^2. Must lie in (0, phi(0))."
        ),
        examples=[0.5],
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
        default="auto",
        description=(
            "Neighbour weights w_ij of eq. (1). 'auto': reciprocal distance for curves "
            "(section 4.2), mean value for meshes and Delaunay neighbourhoods (4.3-4.4), "
            "reciprocal distance for k-NN neighbourhoods."
        ),
    )
    neighborhood: NeighborhoodKind = Field(
        default="delaunay",
        description="Point clouds only: Delaunay neighbourhoods (section 4.4) or plain k-NN.",
    )
    k: int = Field(default=12, ge=3, le=64, description="Point clouds only: neighbours per point.")
    sigma_h: float = Field(
        default=1e-7, gt=0, allow_inf_nan=False, description="Huber threshold of eq. (8)."
    )
    sigma_f: float = Field(
        default=0.5,
        gt=0,
        allow_inf_nan=False,
        description="Width of the Gaussian psi of eq. (10), on curvatures rescaled to [0, 1].",
    )
    tolerance: float = Field(
        default=1e-3,
        gt=0,
        lt=1,
        description="Relative tolerance xi on |phi - tau| / tau (section 6.3).",
    )
    max_iterations: int = Field(
        default=50, ge=1, le=500, description="Cap on lambda iterations of the tau search."
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
        default=1,
        ge=1,
        le=8,
        description="Iterated Tikhonov order k: filter 1 - (mu/(mu+lambda))^k, k solves per "
        "lambda with one factorization (1 = the report's eq. 4).",
    )
    # --- end core-engine block ------------------------------------------------------------
    spectrum: bool = Field(
        default=False,
        description="Also return the singular values of L and the filter factors of eq. (12) "
        "(inputs up to 3000 points).",
    )

    @model_validator(mode="after")
    def _exactly_one_target(self) -> SmoothingParams:
        given = [name for name in ("lam", "tau", "rms") if getattr(self, name) is not None]
        if len(given) != 1:
            raise ValueError(
                "give exactly one of lam, tau or rms"
                + (f" (got {', '.join(given)})" if given else "")
            )
        return self
