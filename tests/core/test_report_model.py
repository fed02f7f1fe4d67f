"""One fact in one place: the members of ``SmoothResult.report()`` are the fields of the one
``Report`` model (service.core.report), both ways, and every report validates against it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from service.core import Geometry, SmoothingParams, smooth
from service.core.report import HistoryEntry, Report, report_example
from tests.core.core_fixtures import noisy_icosphere, polyline_edges

ROOT = Path(__file__).resolve().parents[2]



def _mesh() -> Geometry:
    points, faces = noisy_icosphere(2, 0.01)
    return Geometry(points, faces=faces)


def _cloud(n: int) -> Geometry:
    rng = np.random.default_rng(1)
    xy = rng.uniform(-1, 1, size=(n, 2))
    return Geometry(np.column_stack([xy, 0.2 * np.sin(2 * xy[:, 0]) + rng.normal(0, 0.01, n)]))


def _curve() -> Geometry:
    rng = np.random.default_rng(2)
    t = np.linspace(0, 4 * np.pi, 80)
    points = np.column_stack([np.cos(t), np.sin(t), 0.1 * t]) + rng.normal(0, 0.01, (80, 3))
    return Geometry(points, edges=polyline_edges(80))


#: name -> (input, parameters, members of Report.PRESENT_ONLY it has, what the report says)
CASES: dict[str, tuple[Any, dict[str, Any], set[str], dict[str, Any]]] = {
    "mesh default": (_mesh, {}, set(), {"kind": "mesh", "tau_rule": "auto"}),
    "cloud default": (lambda: _cloud(300), {}, set(), {"kind": "cloud", "tau_rule": "auto"}),
    "curve rms": (_curve, {"rms": 0.005}, set(), {"kind": "curve", "tau_rule": "rms"}),
    "tiled": (lambda: _cloud(1500), {"tau": 3.0, "tile_points": 1000}, {"tiles"}, {}),
    "windowed-sinc": (
        _mesh,
        {"method": "windowed-sinc", "tau": 0.01},
        set(),
        {"method": "windowed-sinc"},
    ),
    "max_deviation": (_mesh, {"max_deviation": 0.01}, set(), {}),
    "spectrum": (_mesh, {"tau": 0.01, "spectrum": True}, {"spectrum"}, {}),
}


def _members() -> set[str]:
    return set(Report.wire_names().values())


@pytest.mark.parametrize("case", sorted(CASES))
def test_report_has_exactly_the_fields_of_the_model(case: str) -> None:
    make, params, present, says = CASES[case]
    report = smooth(make(), SmoothingParams(**params)).report()
    assert {k: report[k] for k in says} == says
    if "max_deviation" in params:
        assert report["bound"]["max_deviation"] == params["max_deviation"]
    Report.model_validate(report)
    keys, fields = set(report), _members()
    assert keys <= fields, f"members no field documents: {keys - fields}"
    expected_absent = set(Report.PRESENT_ONLY) - present
    assert fields - keys == expected_absent, (
        f"{case}: missing {fields - keys - expected_absent}; sent although listed as absent: "
        f"{expected_absent & keys}"
    )


def test_every_field_has_a_description_and_an_example_that_validates() -> None:
    for name, field in Report.model_fields.items():
        assert field.description and field.examples, name
    fields = Report.model_fields.items()
    full = {f.alias or name: (f.examples or [None])[0] for name, f in fields}
    assert Report.model_validate(full).model_dump(by_alias=True) == full
    assert set(Report.PRESENT_ONLY) <= _members()


def test_the_documentation_example_is_the_model_s() -> None:
    example = report_example()
    required = {f.alias or n for n, f in Report.model_fields.items() if f.is_required()}
    assert set(example) == required
    Report.model_validate(example)
    assert Report.model_json_schema()["examples"] == [example]


def test_aliases_lambda_and_the_former_displacement_names() -> None:
    example = report_example()
    by_name = {("lam" if k == "lambda" else k): v for k, v in example.items()}
    assert Report.model_validate(by_name).lam == example["lambda"]
    old = {k: v for k, v in example.items() if not k.endswith("_displacement")}
    old.update(rms_deviation=0.2, max_deviation=0.5)  # a report of a service before 2026-11
    report = Report.model_validate(old)
    assert (report.rms_displacement, report.max_displacement) == (0.2, 0.5)
    dumped = report.model_dump(by_alias=True)
    assert dumped["lambda"] == example["lambda"] and dumped["max_displacement"] == 0.5
    assert "max_deviation" not in dumped and "lam" not in dumped
    assert HistoryEntry.model_validate({"lambda": 1.0, "phi": 2.0}).lam == 1.0
    assert Report.wire_names()["lam"] == "lambda"


def test_the_model_needs_no_web_framework() -> None:
    code = (
        "import sys, service.core.report; "
        "print(sorted(m for m in sys.modules if m.split('.')[0] == 'fastapi' or "
        "m.startswith(('service.api', 'service.io', 'service.jobs'))))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True,
        timeout=120,
    )  # fmt: skip
    assert out.stdout.strip() == "[]", out.stdout
