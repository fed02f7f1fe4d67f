"""Pure numerics of geosmooth (report KU Leuven TW 451): no files, no HTTP, no queue."""

from service.core.errors import (
    DegenerateElement,
    GeometryError,
    GeosmoothError,
    IndexOutOfRange,
    InvalidShape,
    NonFiniteCoordinates,
    ParameterError,
    SolverError,
    TauOutOfRange,
)
from service.core.geometry import Geometry
from service.core.params import SmoothingParams
from service.core.result import SmoothResult, Spectrum
from service.core.smooth import ProgressCallback, smooth

__all__ = [
    "DegenerateElement",
    "Geometry",
    "GeometryError",
    "GeosmoothError",
    "IndexOutOfRange",
    "InvalidShape",
    "NonFiniteCoordinates",
    "ParameterError",
    "ProgressCallback",
    "SmoothResult",
    "SmoothingParams",
    "SolverError",
    "Spectrum",
    "TauOutOfRange",
    "smooth",
]
