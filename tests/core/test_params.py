"""SmoothingParams: exactly one target, documented bounds."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from service.core import SmoothingParams


def test_defaults() -> None:
    p = SmoothingParams(tau=1.0)
    assert (p.laplacian, p.weights, p.neighborhood) == ("normalized", "auto", "delaunay")
    assert (p.sigma_h, p.sigma_f, p.tolerance) == (1e-7, 0.5, 1e-3)


@pytest.mark.parametrize(
    "kw",
    [
        {},
        {"tau": 1, "lam": 1},
        {"tau": 1, "rms": 1},
        {"tau": -1},
        {"rms": 0},
        {"lam": float("nan")},
        {"tau": 1, "k": 2},
        {"tau": 1, "tolerance": 1.5},
        {"tau": 1, "laplacian": "cotan"},
        {"tau": 1, "unknown": 3},
    ],
)
def test_rejected(kw: dict) -> None:
    with pytest.raises(ValidationError):
        SmoothingParams(**kw)


def test_json_schema_has_descriptions() -> None:
    schema = SmoothingParams.model_json_schema()
    assert all("description" in v for v in schema["properties"].values())
