"""The compiled per-face passes (issue 30) give the NumPy expressions' numbers, and those
numbers are right: folds, normals, volumes and edge counts against independent computations."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from service.core import Geometry
from service.core.checks.guards import shape_checks
from service.core.finish import folds, volume
from service.core.finish import tangential as tg
from tests.core.core_fixtures import grid_mesh


def _noisy_sphere(sub: int = 3, noise: float = 0.03, seed: int = 0) -> tuple[np.ndarray, ...]:
    m = trimesh.creation.icosphere(sub)
    P = np.asarray(m.vertices)
    return P + np.random.default_rng(seed).normal(0, noise, P.shape), np.asarray(m.faces)


@pytest.fixture
def compiled(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every mesh takes the compiled path."""
    monkeypatch.setattr(folds, "COMPILED_FROM", 1)


def _both(fn, *args):  # type: ignore[no-untyped-def]
    """``fn(*args)`` on the NumPy path and on the compiled path."""
    numpy_result = fn(*args)
    old = folds.COMPILED_FROM
    folds.COMPILED_FROM = 1
    try:
        return numpy_result, fn(*args)
    finally:
        folds.COMPILED_FROM = old


@pytest.mark.parametrize("noise", [0.0, 0.03, 0.2])
def test_compiled_folds_normals_and_volumes_are_the_numpy_numbers(noise: float) -> None:
    P, F = _noisy_sphere(3, noise)
    a, b = _both(folds.face_normals, P, F)
    np.testing.assert_array_equal(a, b)
    a, b = _both(folds.fold_mask, P, F, len(P))
    np.testing.assert_array_equal(a, b)
    a, b = _both(volume.enclosed_measures, (P, 0.9 * P), F)
    assert a == b


def test_face_normals_and_volume_against_closed_forms(compiled: None) -> None:
    P = np.array([[0.0, 0, 0], [2, 0, 0], [0, 3, 0], [0, 0, 4]])
    F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])  # outward tetrahedron
    N = folds.face_normals(P, F)
    np.testing.assert_array_equal(N[0], [0, 0, -6])  # (0,3,0) x (2,0,0) = (0, 0, -6)
    assert volume.enclosed_measure(P, F) == pytest.approx(2 * 3 * 4 / 6)
    # closed: the other three (area) normals sum to -n_f, so every face of a tetrahedron reads
    # as folded (n_f . (-n_f) < 0)
    assert folds.fold_mask(P, F, 4).all()


def test_a_pushed_vertex_folds_exactly_the_faces_a_loop_finds(compiled: None) -> None:
    P, F = grid_mesh(8, 8)
    P = P.copy()
    P[3 * 8 + 3, 0] += 1.6 / 7  # across its neighbour
    N = np.cross(P[F[:, 1]] - P[F[:, 0]], P[F[:, 2]] - P[F[:, 0]])
    expect = []
    for f, tri in enumerate(F):  # the rule by loops: n_f against the other faces at its corners
        corners = sum(N[g] * len(set(F[g]) & set(tri)) for g in range(len(F)) if g != f)
        expect.append(float(N[f] @ corners) < 0)
    np.testing.assert_array_equal(folds.fold_mask(P, F, len(P)), expect)
    assert any(expect)


def test_edge_counts_and_closedness_on_both_paths() -> None:
    P, F = _noisy_sphere(2)
    for path in _both(volume.edge_counts, F, len(P)):
        a, b, counts = path
        pairs = {tuple(sorted((int(t[i]), int(t[(i + 1) % 3])))) for t in F for i in range(3)}
        assert sorted(zip(a.tolist(), b.tolist(), strict=True)) == sorted(pairs)
        assert np.all(counts == 2)
    open_F = F[1:]
    assert _both(volume.is_closed_mesh, F) == (True, True)
    assert _both(volume.is_closed_mesh, open_F) == (False, False)


def test_valence_irregularity_and_shape_checks_on_both_paths() -> None:
    P, F = _noisy_sphere(3, 0.05)
    a, b = _both(tg.valence_irregularity, F, len(P))
    assert a == b == 0.0
    g = Geometry(P, faces=F)
    X = 0.8 * P + np.random.default_rng(1).normal(0, 0.05, P.shape)
    a, b = _both(shape_checks, g, X)
    assert a == b
    assert a.folded_faces and a.volume_change == pytest.approx(0.8**3 - 1, abs=0.05)
