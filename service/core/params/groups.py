"""Typed views of :class:`~service.core.params.model.SmoothingParams`, one per stage.

The wire format stays flat (one pydantic model); each stage reads the group it needs, so what a
stage depends on is written in its signature. :class:`OperatorParams` is also the operator
cache's key (:func:`service.core.operator.build.operator_key`): its fields are what an operator
depends on, named once.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, TypeVar

__all__ = [
    "BudgetParams",
    "DataParams",
    "FinishParams",
    "OperatorParams",
    "ScaleParams",
    "field_names",
    "view",
]

G = TypeVar("G")


@dataclass(frozen=True)
class OperatorParams:
    """What the Laplacian depends on (report section 4: eqs. 1, 7-10; ends and boundary rows).

    ``displacement``, ``method`` and ``tau`` enter through the boundary rule only
    (:func:`service.core.operator.boundary.boundary_rule`), which the key adds resolved.
    """

    laplacian: str
    weights: str
    neighborhood: str
    k: int
    sigma_h: float
    sigma_f: float
    presmooth: int
    junctions: str
    ends: str
    boundary: str


@dataclass(frozen=True)
class BudgetParams:
    """How lambda is found (section 6): the target, the search, the solver path, eq. (4)'s
    order and the max-norm bound of section 9."""

    lam: float | None
    tau: float | str | None
    rms: float | None
    tolerance: float
    max_iterations: int
    search: str
    solver: str
    method: str
    order: int
    max_deviation: float | None


@dataclass(frozen=True)
class DataParams:
    """The data term's weights omega_i beyond the user's (robust and per-point noise)."""

    robust: str
    noise_weights: str
    outliers: str


@dataclass(frozen=True)
class FinishParams:
    """After the solve: tangential step, volume/area, max-norm clipping, strict shape checks,
    the spectral view (eq. 12)."""

    tangential: str
    preserve_volume: bool
    max_deviation: float | None
    strict: bool
    spectrum: bool


@dataclass(frozen=True)
class ScaleParams:
    """How the run is cut: spatial tiles and fixed boundaries (section 8)."""

    tile_points: int | None
    fix_boundary: bool
    displacement: str


def field_names(group: type[Any]) -> tuple[str, ...]:
    """The :class:`~service.core.params.model.SmoothingParams` fields a group holds, in order."""
    return tuple(f.name for f in dataclasses.fields(group))


def view(params: Any, group: type[G]) -> G:
    """The ``group`` view of ``params`` (a :class:`~service.core.params.model.SmoothingParams`;
    typed loosely so that this module stays below the model that uses it)."""
    return group(**{name: getattr(params, name) for name in field_names(group)})
