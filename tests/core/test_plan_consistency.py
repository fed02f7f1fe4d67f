"""Every Plan entry of a default run is decided (never ``"auto"`` or ``None``) and no two
entries contradict each other (issue 38), on the golden set's inputs and on open meshes in 2 to
5 dimensions; the Plan's outlier count is the report's."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from service.core import smooth
from service.core.geometry import Geometry
from service.core.params import SmoothingParams
from service.core.params.rules import AUTO_NORMAL_MAX_CODIM
from service.core.plan import CHOICES, Plan

#: The entries issue 37 decides with the automatic lambda.
LAMBDA_ENTRIES = ("tau_rule", "search", "solver")


def contradictions(plan: Plan, report: dict[str, Any]) -> list[str]:
    """What in ``plan`` is undecided or disagrees with another entry or with the report."""
    out = [f"{name} undecided" for name in CHOICES
           if getattr(plan, name).value in ("auto", None)]  # fmt: skip
    displacement, boundary = plan.displacement.value, plan.boundary.value
    automatic = plan.boundary.why not in ("given", "default")
    if plan.boundary.evidence.get("mesh") and automatic and (boundary == "curve") != (
        displacement == "free"
    ):
        out.append(f"boundary {boundary!r} with displacement {displacement!r}")
    if plan.boundary.evidence.get("displacement") not in (None, displacement):
        out.append("boundary decided for another displacement")
    if plan.tangential.value == "on" and displacement != "normal":
        out.append("tangential step without normal displacement")
    if report["displacement"] != displacement:
        out.append(f"report displacement {report['displacement']!r}, plan {displacement!r}")
    if plan.outliers.evidence.get("count") != report["outlier_count"]:
        out.append(f"outliers: plan {plan.outliers.evidence.get('count')}, report "
                   f"{report['outlier_count']}")  # fmt: skip
    if report["outlier_count"] and "robust" not in str(plan.data_weights.value):
        out.append("outliers without robust data weights")
    return out


def _golden_inputs() -> list[tuple[str, Any]]:
    from tests.golden.cases import cases, shared_data

    seen, out = set(), []
    for case in cases("quick"):
        name = case.name.rsplit("/", 1)[0]
        if name in seen or (case.name.startswith("shared/") and not shared_data().is_dir()):
            continue
        seen.add(name)
        out.append((name, case.build))
    return out


INPUTS = _golden_inputs()


@pytest.mark.parametrize(("name", "build"), INPUTS, ids=[name for name, _ in INPUTS])
def test_default_plan_of_every_golden_input_is_decided_and_consistent(name: str, build) -> None:  # type: ignore[no-untyped-def]
    import geosmooth

    source, _ = build()
    _, res = geosmooth.smooth(source, {}, full_output=True)
    assert contradictions(res.plan, res.report()) == []


def _open_sheet(dim: int, noise: float, seed: int = 0) -> Geometry:
    """A 12 x 12 grid of triangles (open: it has a boundary) in the first two coordinates of
    ``dim``, with Gaussian noise in every coordinate."""
    u, v = np.meshgrid(np.linspace(0, 1, 12), np.linspace(0, 1, 12))
    P = np.zeros((144, dim))
    P[:, 0], P[:, 1] = u.ravel(), v.ravel()
    if dim > 2:
        P[:, 2] = 0.3 * np.sin(3 * u.ravel()) * np.cos(2 * v.ravel())
    P += noise * np.random.default_rng(seed).standard_normal(P.shape)
    q = np.arange(144).reshape(12, 12)[:-1, :-1].ravel()
    F = np.concatenate([np.column_stack([q, q + 1, q + 13]), np.column_stack([q, q + 13, q + 12])])
    return Geometry(P, faces=F)


@pytest.mark.parametrize("dim", [2, 3, 4, 5])
@pytest.mark.parametrize("noise", [0.0, 0.01])
def test_boundary_follows_displacement_in_any_dimension(dim: int, noise: float) -> None:
    g = _open_sheet(dim, noise)
    res = smooth(g, SmoothingParams(rms=0.005) if noise == 0 else SmoothingParams())
    plan = res.plan
    assert contradictions(plan, res.report()) == []
    expected = "normal" if 1 <= dim - 2 <= AUTO_NORMAL_MAX_CODIM else "free"
    assert plan.displacement.value == expected, plan.displacement
    assert plan.boundary.value == ("curve" if expected == "free" else "ring")


def test_a_flat_open_mesh_falls_back_to_free_displacement_and_its_boundary_rows() -> None:
    """Flat across itself: nothing moves along the normals, ``"auto"`` falls back to free
    displacement, and the boundary rows are then free displacement's (they were "ring")."""
    g = _open_sheet(3, 0.0)
    P = g.points.copy()
    P[:, 2] = 0.0
    P[:, :2] += 0.01 * np.random.default_rng(1).standard_normal((P.shape[0], 2))
    res = smooth(Geometry(P, faces=g.faces), SmoothingParams(rms=0.002))
    assert res.plan.displacement.value == "free"
    assert res.plan.displacement.why.startswith("free: nothing moves along the normals")
    assert res.plan.boundary.value == "curve"
    assert contradictions(res.plan, res.report()) == []


def test_the_lambda_entries_are_decided_too() -> None:
    """The rule, the search and the solver path (issue 37) are decided like the rest."""
    res = smooth(_open_sheet(3, 0.01), SmoothingParams())
    assert [n for n in LAMBDA_ENTRIES if getattr(res.plan, n).value in ("auto", None)] == []
