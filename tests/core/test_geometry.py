"""Geometry validation: only meaningless input is rejected, with typed errors."""

from __future__ import annotations

import numpy as np
import pytest

from service.core import (
    DegenerateElement,
    Geometry,
    IndexOutOfRange,
    InvalidShape,
    NonFiniteCoordinates,
)
from service.core.geometry import mean_spacing


def test_kinds_and_dtypes() -> None:
    P = np.arange(12, dtype=np.int32).reshape(4, 3)
    assert Geometry(P).kind == "cloud"
    assert Geometry(P).points.dtype == np.float64
    assert Geometry(P, edges=[[0, 1], [1, 2]]).kind == "curve"
    assert Geometry(P, faces=[[0, 1, 2]], edges=[[2, 3]]).kind == "mesh"
    assert Geometry(P, faces=np.zeros((0, 3), int)).faces is None


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_points_named_with_first_index(bad: float) -> None:
    P = np.zeros((20, 3))
    P[7, 1] = bad
    P[12, 0] = bad
    with pytest.raises(NonFiniteCoordinates) as info:
        Geometry(P)
    assert info.value.indices == [7, 12]
    assert info.value.field == "geometry.points"
    assert "point 7" in str(info.value)


def test_face_index_out_of_range() -> None:
    with pytest.raises(IndexOutOfRange) as info:
        Geometry(np.zeros((4, 3)), faces=[[0, 1, 2], [1, 2, 9], [0, -1, 2]])
    assert info.value.indices == [1, 2]
    assert info.value.field == "geometry.faces"
    assert "vertex 9" in str(info.value)


def test_edge_index_out_of_range() -> None:
    with pytest.raises(IndexOutOfRange) as info:
        Geometry(np.zeros((4, 2)), edges=[[0, 1], [3, 4]])
    assert info.value.indices == [1] and info.value.field == "geometry.edges"


@pytest.mark.parametrize(
    ("kw", "field"),
    [
        ({"faces": [[0, 1, 2], [2, 3, 2]]}, "geometry.faces"),
        ({"edges": [[1, 1]]}, "geometry.edges"),
    ],
)
def test_elements_repeating_a_vertex(kw: dict, field: str) -> None:
    with pytest.raises(DegenerateElement) as info:
        Geometry(np.zeros((4, 3)), **kw)
    assert info.value.field == field
    assert "repeats a vertex" in str(info.value)


@pytest.mark.parametrize(
    "kw",
    [
        {"points": np.zeros(5)},
        {"points": np.zeros((0, 3))},
        {"points": np.array([["a", "b"]])},
        {"points": np.zeros((3, 3)), "faces": [[0, 1]]},
        {"points": np.zeros((3, 3)), "faces": [[0.5, 1, 2]]},
        {"points": np.zeros((3, 3)), "weights": [1.0, 2.0]},
        {"points": np.zeros((3, 3)), "fixed": [0.5]},
    ],
)
def test_malformed_arrays_are_rejected_as_invalid_shape(kw: dict) -> None:
    with pytest.raises(InvalidShape):
        Geometry(**kw)


def test_weights_and_fixed() -> None:
    g = Geometry(np.zeros((4, 3)), weights=[1.0, np.inf, 2.0, 1.0], fixed=[3, 3])
    assert g.fixed_mask().tolist() == [False, True, False, True]
    assert g.omega().tolist() == [1.0, 1.0, 2.0, 1.0]
    with pytest.raises(NonFiniteCoordinates):
        Geometry(np.zeros((2, 3)), weights=[1.0, 0.0])
    with pytest.raises(NonFiniteCoordinates):
        Geometry(np.zeros((2, 3)), weights=[1.0, np.nan])
    with pytest.raises(IndexOutOfRange) as info:
        Geometry(np.zeros((2, 3)), fixed=[0, 2])
    assert info.value.field == "geometry.fixed"


def test_mean_spacing_of_a_cloud_with_thousands_of_copies() -> None:
    """20,000 copies of two points beside 2,000 distinct ones (issue 42 item 5): the copies'
    nearest other point is at 0, the rest's by brute force; no quadratic k-d tree search."""
    rng = np.random.default_rng(4)
    Q = rng.normal(size=(2000, 3))
    P = np.vstack([Q, np.repeat(Q[:2], 10000, axis=0)])[rng.permutation(22000)]
    D = np.linalg.norm(Q[:, None] - Q[None], axis=2)
    np.fill_diagonal(D, np.inf)
    nearest = D.min(axis=1)
    nearest[:2] = 0.0  # the copied points
    expected = np.sum(nearest[2:]) / 22000  # 20,002 points at 0
    assert mean_spacing(Geometry(P)) == pytest.approx(expected, rel=1e-12)
