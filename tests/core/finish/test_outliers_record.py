"""Outliers are one record (issue 38): the Plan's count, the report's ``outlier_count`` and
the warning's number are the finish stage's :class:`Outliers`, on noisy meshes and clouds."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from service.core import smooth
from service.core.geometry import Geometry
from service.core.params import SmoothingParams

cases = pytest.importorskip("benchmarks.quality.cases")

RUNS = [
    (key, params)
    for key in ("sphere-2.5K/outliers-0.25", "spot/iso-0.25", "fandisk/aniso-0.25")
    for params in ({}, {"outliers": "flag"}, {"robust": "huber"})
] + [("cloud-sphere/aniso-0.5", {}), ("sphere-2.5K/outliers-0.5", {"outliers": "pull"})]


@pytest.mark.parametrize(("key", "params"), RUNS, ids=[f"{k}-{p}" for k, p in RUNS])
def test_plan_report_and_warning_count_the_same_outliers(key: str, params: dict[str, Any]) -> None:
    case = cases.make_case(key)
    g = Geometry(case.points, faces=case.shape.faces, edges=case.shape.edges)
    res = smooth(g, SmoothingParams(**params))
    report = res.report()
    count = report["outlier_count"]
    assert res.plan is not None and res.plan.outliers.evidence["count"] == count
    assert np.array_equal(np.sort(res.outliers), res.outliers) and len(set(res.outliers)) == count
    said = {w.code: w.numbers for w in res.warnings}
    if res.plan.outliers.value == "pull":
        assert said.get("outliers", {}).get("count", 0) == count
    else:  # flag, drop: those found and the points the solve moved far
        found = said.get("outliers", {}).get("count", 0)
        assert found + said.get("outliers-moved-far", {}).get("count", 0) == count
    details = [d["code"] for d in report["warning_details"]]
    assert [w.message for w in res.warnings] == report["warnings"] and len(details) == len(
        report["warnings"]
    )
