"""Typed errors of the smoothing engine.

Every error names the problem, the field at fault (a dotted path such as ``geometry.faces`` or
``params.tau``, used by the HTTP layer for RFC 9457 problem details) and, where it applies, the
first offending indices. Each class also carries its presentation metadata as class attributes
(``title``, HTTP ``status``, CLI ``exit_code``): the HTTP problem mapping (``service.api``), the
job problems (``service.jobs``) and the CLI read them, so adding an error class touches this file
only.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import ClassVar

__all__ = [
    "DegenerateElement",
    "GeometryError",
    "GeosmoothError",
    "IndexOutOfRange",
    "InvalidShape",
    "NonFiniteCoordinates",
    "ParameterError",
    "ShapeLost",
    "SolverError",
    "TauOutOfRange",
]

_MAX_LISTED = 10


class GeosmoothError(ValueError):
    """Base class of every error the engine raises on bad input.

    Parameters
    ----------
    message : str
        Human readable, one line.
    field : str
        Dotted path of the input at fault, e.g. ``"geometry.points"``.
    indices : sequence of int, optional
        First offending indices (at most ten are kept).
    """

    code: ClassVar[str] = "geosmooth-error"
    #: Problem title (RFC 9457 ``title``), HTTP status and CLI exit status of this error class.
    title: ClassVar[str] = "Invalid input"
    status: ClassVar[int] = 422
    exit_code: ClassVar[int] = 4  # see the CLI's table, service/exit_codes.py

    def __init__(self, message: str, *, field: str, indices: Sequence[int] | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.field = field
        self.indices: list[int] = [int(i) for i in list(indices or [])[:_MAX_LISTED]]

    def to_dict(self) -> dict[str, object]:
        """Machine-readable form (used in job records and problem details)."""
        out: dict[str, object] = {"code": self.code, "message": self.message, "field": self.field}
        if self.indices:
            out["indices"] = self.indices
        return out


class GeometryError(GeosmoothError):
    """The geometry has no meaning as smoothing input."""

    code = "invalid-geometry"
    title = "Invalid geometry"


class InvalidShape(GeometryError):
    """Arrays of the wrong rank, width or type."""

    code = "invalid-shape"


class NonFiniteCoordinates(GeometryError):
    """NaN or infinite coordinates (or per-point weights)."""

    code = "non-finite-coordinates"


class IndexOutOfRange(GeometryError):
    """A face, edge or fixed index outside ``[0, n)``."""

    code = "index-out-of-range"


class DegenerateElement(GeometryError):
    """A face or an edge that repeats a vertex."""

    code = "degenerate-element"


class ParameterError(GeosmoothError):
    """Parameters that cannot be applied to this geometry."""

    code = "invalid-parameter"
    title = "Invalid parameters"


class TauOutOfRange(ParameterError):
    """The smoothing factor lies outside ``(0, phi(0))`` (report section 6.3).

    Attributes
    ----------
    tau : float
        The requested smoothing factor.
    tau_max : float
        ``phi(0) = ||D(P - P_bar)||_F^2``; the valid range is the open interval ``(0, tau_max)``.
    """

    code = "tau-out-of-range"

    def __init__(self, message: str, *, field: str, tau: float, tau_max: float) -> None:
        super().__init__(message, field=field)
        self.tau = tau
        self.tau_max = tau_max

    def to_dict(self) -> dict[str, object]:
        out = super().to_dict()
        out["tau"] = self.tau
        out["valid_range"] = [0.0, self.tau_max]
        return out


class SolverError(GeosmoothError):
    """The linear solver failed (e.g. a matrix that is not positive definite)."""

    code = "solver-failed"
    title = "The input cannot be solved"
    exit_code = 5


class ShapeLost(GeosmoothError):
    """``strict=True`` and a shape check warned: the result lost shape (folds the input did not
    have, volume, area or length changed beyond what removing the noise explains).

    Attributes
    ----------
    warnings : list of str
        The shape checks' warnings (each names the parameter to change).
    checks : dict
        The measurements behind them (``service.core.checks.guards.ShapeChecks``).
    """

    code = "shape-lost"
    title = "Smoothing lost shape (strict mode)"
    status = 422
    exit_code = 12

    def __init__(self, warnings: Sequence[str], checks: dict[str, object]) -> None:
        super().__init__(
            "the result lost shape: " + "; ".join(warnings), field="params.strict"
        )
        self.warnings = list(warnings)
        self.checks = dict(checks)

    def to_dict(self) -> dict[str, object]:
        out = super().to_dict()
        out["warnings"] = self.warnings
        out["checks"] = self.checks
        return out
