"""Pure numerics of geosmooth (report KU Leuven TW 451): no files, no HTTP, no queue.

The public names are loaded lazily (PEP 562), so that importing ``service.core.params`` (the
CLI's ``--help``, the API's schemas) does not load scipy and the solver.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

_EXPORTS = {
    "DegenerateElement": "errors",
    "GeometryError": "errors",
    "GeosmoothError": "errors",
    "IndexOutOfRange": "errors",
    "InvalidShape": "errors",
    "NonFiniteCoordinates": "errors",
    "ParameterError": "errors",
    "SolverError": "errors",
    "TauOutOfRange": "errors",
    "Geometry": "geometry",
    "SmoothingParams": "params",
    "SmoothResult": "result",
    "Spectrum": "result",
    "ProgressCallback": "progress",
    "ProgressEvent": "progress",
    "smooth": "entry",
    "build_operator": "operator.build",
    "SmoothingOperator": "operator.build",
}

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
    "ProgressEvent",
    "SmoothResult",
    "SmoothingOperator",
    "SmoothingParams",
    "SolverError",
    "Spectrum",
    "TauOutOfRange",
    "build_operator",
    "smooth",
]

if TYPE_CHECKING:  # pragma: no cover
    from service.core.entry import smooth
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
    from service.core.operator.build import SmoothingOperator, build_operator
    from service.core.params import SmoothingParams
    from service.core.progress import ProgressCallback, ProgressEvent
    from service.core.result import SmoothResult, Spectrum


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'service.core' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"service.core.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
