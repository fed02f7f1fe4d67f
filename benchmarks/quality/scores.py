"""Quality metrics of a result against the ground truth of its case.

* ``vertex``: RMS of ``||x_i - q_i||`` (``q_i`` the clean position), as a fraction of the
  noisy input's;
* ``surface``: RMS distance of the ``x_i`` to the true surface or curve, as a fraction of the
  input's;
* ``normal_deg``: mean angle (degrees) between the result's normals and the true ones (meshes:
  area-weighted vertex normals; curves: tangents; clouds: PCA normals of 12 neighbours;
  unsigned);
* ``volume_pct`` / ``area_pct``: change of enclosed volume (closed meshes; area for closed 2-D
  polygons) and of surface area (meshes), in percent;
* ``flipped``: faces whose normal points against the clean mesh's (meshes).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from benchmarks.metrics import measure_change
from benchmarks.quality.cases import Case
from benchmarks.quality.shapes import vertex_normals

__all__ = ["Scorer", "face_normals", "flipped_faces"]

FloatArray = NDArray[np.float64]


def face_normals(points: FloatArray, faces: NDArray[np.int64]) -> FloatArray:
    """Unnormalized face normals (twice the area)."""
    a, b, c = (points[faces[:, i]] for i in range(3))
    return np.cross(b - a, c - a)


def flipped_faces(X: FloatArray, reference: FloatArray, faces: NDArray[np.int64]) -> int:
    """Faces whose normal on ``X`` has a negative dot product with the one on ``reference``."""
    return int(np.sum(np.einsum("ij,ij->i", face_normals(X, faces),
                                face_normals(reference, faces)) < 0))


def _pca_normals(X: FloatArray, k: int = 12) -> FloatArray:
    _, idx = cKDTree(X).query(X, k=k)
    Q = X[idx] - X[idx].mean(axis=1, keepdims=True)
    _, vecs = np.linalg.eigh(np.einsum("nki,nkj->nij", Q, Q))
    return vecs[:, :, 0]


def _curve_tangents(X: FloatArray, edges: NDArray[np.int64]) -> FloatArray:
    t = np.zeros_like(X)
    d = X[edges[:, 1]] - X[edges[:, 0]]
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)
    # orient each edge direction consistently with its endpoint's accumulated tangent
    for col in (0, 1):
        np.add.at(t, edges[:, col], d)
    nrm = np.linalg.norm(t, axis=1, keepdims=True)
    return np.divide(t, nrm, out=np.zeros_like(t), where=nrm > 0)


def _angles(a: FloatArray, b: FloatArray) -> FloatArray:
    c = np.abs(np.einsum("ij,ij->i", a, b))
    return np.degrees(np.arccos(np.clip(c, 0.0, 1.0)))


class Scorer:
    """Scores results on one case; the noisy input's errors are the reference for fractions."""

    def __init__(self, case: Case) -> None:
        self.case = case
        shape = case.shape
        self.truth = shape.points
        self.v_in = self._rms_vertex(case.points)
        self.s_in = self._rms_surface(case.points)
        if shape.kind == "curve":
            assert shape.edges is not None
            self.true_dir = shape.frame[:, :, -1]
        else:
            self.true_dir = shape.normals

    def _rms_vertex(self, X: FloatArray) -> float:
        return float(np.sqrt(np.mean(np.sum((X - self.truth) ** 2, axis=1))))

    def _rms_surface(self, X: FloatArray) -> float:
        return float(np.sqrt(np.mean(self.case.shape.distance(X) ** 2)))

    def _directions(self, X: FloatArray) -> FloatArray:
        shape = self.case.shape
        if shape.faces is not None:
            return vertex_normals(X, shape.faces)
        if shape.edges is not None:
            return _curve_tangents(X, shape.edges)
        return _pca_normals(X)

    def quick(self, X: FloatArray) -> tuple[float, float]:
        """(vertex, surface) error fractions: what sweeps select on."""
        return self._rms_vertex(X) / self.v_in, self._rms_surface(X) / self.s_in

    def full(self, X: FloatArray) -> dict[str, Any]:
        """Every metric of the module docstring."""
        shape = self.case.shape
        v, s = self.quick(X)
        out: dict[str, Any] = {"vertex": v, "surface": s}
        ang = _angles(self._directions(X), self.true_dir)
        if shape.kind == "curve":
            assert shape.edges is not None
            deg = np.bincount(shape.edges.ravel(), minlength=shape.n)
            ang = ang[deg == 2]  # tangents are defined at degree-2 vertices only
        out["normal_deg"] = float(np.mean(ang))
        out["volume_pct"] = None
        out["area_pct"] = None
        out["flipped"] = None
        if shape.closed and (shape.faces is not None or shape.points.shape[1] == 2):
            out["volume_pct"] = measure_change(X, self.truth, shape.faces, shape.edges)
        if shape.faces is not None:
            a0 = np.linalg.norm(face_normals(self.truth, shape.faces), axis=1).sum()
            a1 = np.linalg.norm(face_normals(X, shape.faces), axis=1).sum()
            out["area_pct"] = 100.0 * (a1 - a0) / a0
            out["flipped"] = flipped_faces(X, self.truth, shape.faces)
        return out
