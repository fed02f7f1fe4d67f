"""The Plan (issue 29): every automatic choice once, with its evidence, in the report; the
typed parameter groups and the operator key computed from the operator group."""

from __future__ import annotations

import dataclasses
import json

import numpy as np

from service.core import Geometry, SmoothingParams, smooth
from service.core.operator.build import build_operator, operator_key
from service.core.params import (
    BudgetParams,
    DataParams,
    FinishParams,
    OperatorParams,
    ScaleParams,
)
from service.core.plan import CHOICES, make_plan


def _sphere(n: int = 400, noise: float = 0.01) -> Geometry:
    rng = np.random.default_rng(1)
    P = rng.normal(size=(n, 3))
    P /= np.linalg.norm(P, axis=1)[:, None]
    return Geometry(P + noise * rng.normal(size=P.shape))


def test_the_report_carries_every_choice_as_json() -> None:
    result = smooth(_sphere(), SmoothingParams())
    plan = result.report()["plan"]
    assert tuple(plan) == CHOICES
    assert all(set(choice) == {"value", "why", "evidence"} for choice in plan.values())
    json.dumps(plan)
    assert plan["displacement"]["value"] == result.displacement == "normal"
    assert plan["solver"]["value"] == result.solver
    assert plan["tau_rule"]["evidence"]["tau"] == result.tau


def test_the_plan_resolves_auto_once_and_keeps_the_operator_key() -> None:
    geometry = _sphere()
    params = SmoothingParams(weights="auto")
    plan = make_plan(geometry, params)
    assert plan.params.weights == plan.weights.value == "mean-value"
    assert "auto" not in (plan.params.ends, plan.params.boundary, plan.params.displacement)
    assert operator_key(geometry, plan.params) == operator_key(geometry, params)
    op = build_operator(geometry, params)
    assert smooth(geometry, params, operator=op).weights == "mean-value"


def test_the_groups_partition_the_flat_fields() -> None:
    groups = (OperatorParams, BudgetParams, DataParams, FinishParams, ScaleParams)
    names = [f.name for g in groups for f in dataclasses.fields(g)]
    flat = set(SmoothingParams.model_fields) - {"preset"}
    assert set(names) == flat  # max_deviation sits in budget (section 9's search) and finish
    assert SmoothingParams(k=7).operator.k == 7
