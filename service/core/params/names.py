"""The choices of each parameter (``Literal`` names), the bounds and defaults written once, and
the report's preset: what :class:`~service.core.params.model.SmoothingParams` and the API's
per-key bounds (their defaults in ``service.settings``) read."""

from __future__ import annotations

from typing import Any, Literal

__all__ = [
    "MAX_ITERATIONS",
    "MAX_ITERATIONS_BOUND",
    "MAX_K",
    "REPORT_PRESET",
    "SPECTRUM_MAX_POINTS",
    "TOLERANCE",
    "Boundary",
    "Displacement",
    "Ends",
    "Junctions",
    "LaplacianVariant",
    "MethodName",
    "NeighborhoodKind",
    "NoiseWeights",
    "OutlierMode",
    "Preset",
    "RobustRule",
    "SearchName",
    "SolverName",
    "Tangential",
    "TauRule",
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
TauRule = Literal["auto", "gcv"]
RobustRule = Literal["auto", "none", "huber", "tukey"]
NoiseWeights = Literal["auto", "none", "local"]
OutlierMode = Literal["auto", "flag", "drop", "pull"]
Displacement = Literal["auto", "free", "normal"]
Tangential = Literal["auto", "off"]
Preset = Literal["report"]
Junctions = Literal["corner", "smooth"]
Ends = Literal["auto", "pulled", "fixed"]
Boundary = Literal["auto", "ring", "curve"]

# Bounds and defaults written once: the fields below, the API's per-key bounds (their defaults
# in service.settings) and the defaults of the search functions read them.
#: Default relative tolerance xi on |phi - tau| / tau (section 6.3).
TOLERANCE = 1e-3
#: Default and largest cap on lambda iterations of the tau search.
MAX_ITERATIONS, MAX_ITERATIONS_BOUND = 50, 500
#: Largest neighbours per point (k-NN with k = 64 already gives ~4000 entries per row of L^T L).
MAX_K = 64
#: Largest input (free points) for which the dense SVD of the spectral view is computed.
SPECTRUM_MAX_POINTS = 3000

#: ``preset="report"``: the choices of report TW 451, for every field the caller does not give.
REPORT_PRESET: dict[str, Any] = {
    "laplacian": "normalized",
    "weights": "auto",
    "neighborhood": "delaunay",
    "k": 12,
    "robust": "none",
    "noise_weights": "none",
    "displacement": "free",
    "tangential": "off",
    "presmooth": 0,
    "junctions": "smooth",
    "ends": "pulled",
    "boundary": "ring",
    "order": 1,
    "method": "tikhonov",
    "search": "rational",
    "solver": "cholmod",
}
