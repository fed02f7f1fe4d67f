"""SmoothingParams: at most one target (none: automatic tau), documented bounds, preset."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from service.core import SmoothingParams


def test_defaults_are_the_benchmark_s_and_preset_report_restores_the_report_s() -> None:
    p = SmoothingParams(tau=1.0)
    assert (p.laplacian, p.weights, p.neighborhood) == ("normalized", "uniform", "delaunay")
    assert p.k == 20
    assert (p.order, p.displacement, p.presmooth, p.junctions) == (2, "auto", 2, "corner")
    assert (p.sigma_h, p.sigma_f, p.tolerance) == (1e-7, 0.5, 1e-3)
    r = SmoothingParams(tau=1.0, preset="report")  # the report's choices
    assert (r.weights, r.k, r.order, r.displacement, r.presmooth, r.search) == (
        "auto", 12, 1, "free", 0, "rational")


@pytest.mark.parametrize(
    "kw",
    [
        {"tau": "fast"},
        {"tau": float("inf")},
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
def test_invalid_values_are_rejected(kw: dict) -> None:
    with pytest.raises(ValidationError):
        SmoothingParams(**kw)


def test_json_schema_has_descriptions() -> None:
    schema = SmoothingParams.model_json_schema()
    assert all("description" in v for v in schema["properties"].values())


@pytest.mark.parametrize(
    ("kw", "rule"),
    [({}, "auto"), ({"tau": "auto"}, "auto"), ({"tau": "gcv"}, "gcv"), ({"tau": "0.5"}, "tau"),
     ({"rms": 1}, "rms"), ({"lam": 1}, "lam")],
)
def test_tau_rule_names_the_target_given(kw: dict, rule: str) -> None:
    p = SmoothingParams(**kw)
    assert p.tau_rule == rule
    assert p.tau is None or p.tau in ("auto", "gcv") or p.tau == 0.5


def test_tau_errors_are_located_at_tau() -> None:
    with pytest.raises(ValidationError) as info:
        SmoothingParams(tau=-1)
    (err,) = info.value.errors()
    assert err["loc"] == ("tau",) and err["type"] == "greater_than"


def test_report_preset_fills_only_what_is_not_given() -> None:
    p = SmoothingParams(tau=1.0, preset="report", weights="uniform")
    assert (p.weights, p.laplacian, p.displacement, p.k) == ("uniform", "normalized", "free", 12)
    assert SmoothingParams(tau=1.0, preset="report").weights == "auto"
