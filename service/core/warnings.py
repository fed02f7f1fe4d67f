"""Typed warnings of the smoothing engine: what the user should know about a run that did not
fail, as records (issue 38).

A warning is a :class:`EngineWarning`: a stable ``code`` (kebab-case, listed with its meaning
in :data:`CODES`), the numbers it rests on (``values``) and its message in words. The stage
that finds it returns it in its record (the problem's, the data weights', the outliers', the
checks'); nothing matches or rewrites a message. The report maps them in one place
(:func:`to_wire`): ``warnings`` keeps the messages (the wire format of every report so far),
``warning_details`` adds each one's code and numbers.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

__all__ = ["CODES", "LEGACY", "EngineWarning", "to_wire", "warning"]

Value = bool | int | float | str | None

#: The code of a note the lambda search still writes as a string (``service/core/search``).
LEGACY = "search"

#: Every warning code and what it means (the report's ``warning_details[].code``).
CODES: Mapping[str, str] = {
    "fix-boundary-ignored": "fix_boundary on k-NN neighbourhoods: no boundary is defined",
    "data-weights-not-applied": "the input has weights: no automatic robust or noise weights",
    "uneven-noise": "the noise varies across the input: weights 1/sigma_i applied",
    "outliers": "points far from the surface treated as outliers (flagged, dropped or pulled)",
    "outliers-moved-far": "points the solve moved far kept in place as outliers too",
    "matrix-free": "the matrix-free path was chosen over a factorization (memory, density)",
    "solver-accuracy": "conjugate gradients stopped before their accuracy bound",
    "solver-fallback": "CHOLMOD is missing: SciPy's SuperLU was used",
    "filter-tau-not-met": "windowed-sinc: no pass band of the degree meets tau",
    "not-smoothed": "the automatic tau found nothing to smooth: the input is returned",
    "nothing-to-smooth": "nothing can move: the input is returned unchanged",
    "max-deviation": "the max-norm bound of section 9 could not be met as asked",
    "shape": "a shape check: the shape was smoothed away rather than the noise",
    "folds-kept": "faces folded in the input stay folded in the result",
    "spectrum-unavailable": "the spectrum (eq. 12) was asked for but not computed",
    "halo-capped": "tiles: the halo was capped, seams may show",
    "residual-backoff": "the residual test found shape in the removed displacement: backed off",
    "risk-at-floor": "the risk estimate's minimum is at full smoothing: the discrepancy budget",
    LEGACY: "a note of the lambda search not yet typed (service/core/search)",
}


@dataclass(frozen=True)
class EngineWarning:
    """One warning: its code, its message and the numbers behind it.

    Attributes
    ----------
    code : str
        One of :data:`CODES`.
    message : str
        One sentence for the user (names the parameter to change where one would help).
    values : tuple of (str, value)
        The numbers the message states, by name (hashable, so tiles can merge warnings).
    """

    code: str
    message: str
    values: tuple[tuple[str, Value], ...] = ()

    def __str__(self) -> str:
        return self.message

    @property
    def numbers(self) -> dict[str, Value]:
        """``values`` as a dict."""
        return dict(self.values)

    def to_dict(self) -> dict[str, Any]:
        """``{"code", "message", "values"}`` (JSON-ready)."""
        return {"code": self.code, "message": self.message, "values": self.numbers}


def warning(code: str, message: str, **values: Any) -> EngineWarning:
    """A warning of a known ``code`` (a :class:`KeyError` for an unknown one: a programming
    error, caught by the tests); numpy scalars among ``values`` become Python numbers."""
    if code not in CODES:
        raise KeyError(f"unknown warning code {code!r}")
    plain = {k: v.item() if hasattr(v, "item") else v for k, v in values.items()}  # numpy
    return EngineWarning(code, message, tuple(plain.items()))


def to_wire(warnings: Iterable[EngineWarning]) -> dict[str, list[Any]]:
    """The report's members: ``warnings`` (messages, run order) and ``warning_details``."""
    ws = list(warnings)
    return {"warnings": [w.message for w in ws], "warning_details": [w.to_dict() for w in ws]}
