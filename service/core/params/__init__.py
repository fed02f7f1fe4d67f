"""Smoothing parameters: the flat :class:`SmoothingParams` (the one wire format the library,
CLI, HTTP API and job queue share, :mod:`.model`) and its typed views per stage
(:mod:`.groups`: operator, budget, data, finish, scale) with the one free-vs-normal rule
(:mod:`.rules`).

Importing this package loads pydantic only (no numpy, no scipy): the CLI's ``--help`` and the
API's schemas import it.
"""

from service.core.params.groups import (
    BudgetParams,
    DataParams,
    FinishParams,
    OperatorParams,
    ScaleParams,
)
from service.core.params.model import SmoothingParams
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

__all__ = [
    "MAX_ITERATIONS",
    "MAX_ITERATIONS_BOUND",
    "MAX_K",
    "REPORT_PRESET",
    "SPECTRUM_MAX_POINTS",
    "TOLERANCE",
    "Boundary",
    "BudgetParams",
    "DataParams",
    "Displacement",
    "Ends",
    "FinishParams",
    "Junctions",
    "LaplacianVariant",
    "MethodName",
    "NeighborhoodKind",
    "NoiseWeights",
    "OperatorParams",
    "OutlierMode",
    "Preset",
    "RobustRule",
    "ScaleParams",
    "SearchName",
    "SmoothingParams",
    "SolverName",
    "Tangential",
    "TauRule",
    "WeightScheme",
]
