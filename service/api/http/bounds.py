"""The bounds that apply to one API key (a plain dataclass: worker processes unpickle it).

Defaults are the settings of the same names; a keys file can override any of them per key
(see :mod:`service.api.http.auth`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

__all__ = ["BoundError", "Limits"]


class BoundError(ValueError):
    """An override that is not a known, positive bound (the keys file reports where)."""


@dataclass(frozen=True)
class Limits:
    """Bounds of one key (defaults: the settings of the same names; see the API README).

    Attributes
    ----------
    max_upload_bytes : int
        Largest request body (413).
    max_points, max_faces : int
        Largest input of ``POST /v1/jobs`` (413).
    sync_max_points : int
        Largest input of ``POST /v1/smooth`` (413).
    max_k, max_iterations : int
        Largest ``params.k`` and ``params.max_iterations`` (422).
    max_spectrum_points : int
        Largest input for which ``params.spectrum`` may be asked (422).
    rate_limit, rate_burst : float, int
        Token bucket of the key's requests (429).
    max_active_jobs : int
        Queued plus running jobs of the key (429).
    max_sync_per_key : int
        Concurrent ``POST /v1/smooth`` of the key (429).
    """

    max_upload_bytes: int
    max_points: int
    max_faces: int
    sync_max_points: int
    max_k: int
    max_iterations: int
    max_spectrum_points: int
    rate_limit: float
    rate_burst: int
    max_active_jobs: int
    max_sync_per_key: int

    @classmethod
    def from_settings(cls, settings: Any) -> Limits:
        """The default bounds: the settings' fields of the same names."""
        return cls(**{f.name: getattr(settings, f.name) for f in dataclasses.fields(cls)})

    def with_overrides(self, overrides: Mapping[str, str]) -> Limits:
        """These bounds with ``name=value`` overrides.

        Raises
        ------
        BoundError
            An unknown name, a value that is not a number, or one that is not positive.
        """
        types = {f.name: f.type for f in dataclasses.fields(self)}
        values: dict[str, Any] = {}
        for name, text in overrides.items():
            if name not in types:
                raise BoundError(f"unknown bound {name!r}")
            try:
                value = float(text) if types[name] in ("float", float) else int(text)
            except ValueError:
                raise BoundError(f"{name}={text!r} is not a number") from None
            if not value > 0:
                raise BoundError(f"{name} must be positive")
            values[name] = value
        return dataclasses.replace(self, **values)
