"""Issue 40's families: every phenomenon in both halves, exact truths checked against closed
forms."""

from __future__ import annotations

import numpy as np

from benchmarks.quality import harm
from benchmarks.quality import harmshapes as hs


def test_every_phenomenon_in_both_halves() -> None:
    halves: dict[str, set[str]] = {}
    for ph, _, _, half, _ in harm.FAMILIES.values():
        halves.setdefault(ph, set()).add(half)
    assert all(h == {"calibration", "test"} for h in halves.values()), halves
    assert set(harm.cases("calibration")).isdisjoint(harm.cases("test"))


def test_cylinder_is_a_closed_prism_of_known_volume_and_aspect() -> None:
    s = hs.cylinder(20, ntheta=200, height=1.9)
    F = s.faces
    assert F is not None
    vol = np.sum(s.points[F[:, 0]] * np.cross(s.points[F[:, 1]], s.points[F[:, 2]])) / 6
    assert np.isclose(vol, 100 * np.sin(2 * np.pi / 200) * 1.9)  # n/2 sin(2 pi/n) r^2 h
    assert np.bincount(F.ravel()).max() == 200  # the caps' hubs
    assert np.allclose(s.distance(s.points), 0.0, atol=1e-12)
    q = np.array([[0.0, 0.0, 0.95], [1.5, 0.0, 0.95], [0.0, 0.0, 2.4]])
    assert np.allclose(s.distance(q), [0.95, 0.5, 0.5])


def test_fold_and_plate_distances() -> None:
    f = hs.fold(2.2)
    g = 2.2 * 0.05
    assert np.allclose(f.distance(f.points), 0.0, atol=1e-12)
    q = np.array([[0.8, 0.6, 0.5 * g], [0.8, 0.6, -0.3], [0.8, -0.2, 0.0]])
    assert np.allclose(f.distance(q), [0.5 * g, 0.3, 0.2])  # between layers, below, off the end
    p = hs.plate(0.3)
    assert np.allclose(p.distance(p.points), 0.0, atol=1e-9)


def test_duplicates_copy_the_noise_and_holes_have_boundaries() -> None:
    c = harm.make("dup-a/0.25")
    pairs = c.shape.extra["copies"]
    assert isinstance(pairs, np.ndarray) and len(pairs) == 25
    assert np.array_equal(c.points[pairs[:, 0]], c.points[pairs[:, 1]])
    s = hs.holed_plate(9)
    assert s.faces is not None and hs.boundary_vertices(s.faces, s.n).sum() > 9 * 20
