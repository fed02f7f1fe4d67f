"""Normals recomputed from smoothed geometry (written in place of the input's normals).

* Meshes: area-weighted vertex normals, ``n_i = sum over faces f of i of (e1 x e2)_f`` (the cross
  product is twice the face area times its unit normal), normalised. Vertices in no face keep
  their input normal. The winding decides the orientation; if most vertices disagree with the
  input's normals (a file written with the opposite convention), all are flipped once.
* Polygons with a per-corner normal index (OBJ ``f v//vn``): each normal index gets the
  normalised sum of the Newell normals (area-weighted) of the polygons whose corners use it, so
  split normals along creases stay split.
* Point clouds: the eigenvector of the smallest eigenvalue of the covariance of the ``k`` nearest
  neighbours (PCA), each flipped to agree with the input's normal at that point (the only
  orientation a cloud has). Computed in blocks, so memory stays ``O(block * k)``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "cloud_normals",
    "corner_normals",
    "mesh_normals",
    "orient_globally",
    "orient_pointwise",
    "unit_rows",
]

_BLOCK = 65536


def unit_rows(v: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Rows scaled to unit length; also the mask of rows that had a usable length."""
    norm = np.linalg.norm(v, axis=1)
    ok = norm > 0
    out = np.zeros_like(v)
    out[ok] = v[ok] / norm[ok, None]
    return out, ok


def mesh_normals(points: NDArray[np.float64], faces: NDArray[np.int64]) -> NDArray[np.float64]:
    """Area-weighted vertex normals; rows of vertices in no (non-degenerate) face are zero."""
    p = points[:, :3] if points.shape[1] >= 3 else np.column_stack([points, np.zeros(len(points))])
    acc = np.zeros((len(p), 3))
    for s in range(0, len(faces), _BLOCK):
        f = faces[s : s + _BLOCK]
        a, b, c = p[f[:, 0]], p[f[:, 1]], p[f[:, 2]]
        fn = np.cross(b - a, c - a)
        for corner in range(3):
            for j in range(3):
                acc[:, j] += np.bincount(f[:, corner], weights=fn[:, j], minlength=len(p))
    return unit_rows(acc)[0]


def corner_normals(
    points: NDArray[np.float64],
    flat: NDArray[np.int64],
    counts: NDArray[np.int64],
    normal_index: NDArray[np.int64],
    n_normals: int,
) -> NDArray[np.float64]:
    """Normals indexed per polygon corner (OBJ ``vn``), recomputed by Newell's method.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        Vertex positions.
    flat, counts : ndarray of int
        Polygon corners (vertex indices, concatenated) and corners per polygon.
    normal_index : ndarray of int, shape like ``flat``
        Normal index of each corner, ``-1`` where the corner has none.
    n_normals : int
        Number of normals in the file.
    """
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    poly = np.repeat(np.arange(counts.size), counts)
    nxt = np.arange(flat.size) + 1
    last = starts + counts - 1
    nxt[last] = starts  # wrap around within each polygon
    p = points[flat]
    q = points[flat[nxt]]
    cross = np.cross(p, q)
    poly_n = np.zeros((counts.size, 3))
    for j in range(3):
        poly_n[:, j] = np.bincount(poly, weights=cross[:, j], minlength=counts.size)
    acc = np.zeros((n_normals, 3))
    has = normal_index >= 0
    for j in range(3):
        acc[:, j] = np.bincount(
            normal_index[has], weights=poly_n[poly[has], j], minlength=n_normals
        )
    return unit_rows(acc)[0]


def cloud_normals(
    points: NDArray[np.float64], k: int = 16, only: NDArray[np.int64] | None = None
) -> NDArray[np.float64]:
    """PCA normals from the ``k`` nearest neighbours (unoriented, unit length).

    ``only``: compute them for these points (their neighbours are searched among all).
    """
    from scipy.spatial import cKDTree

    p = points[:, :3] if points.shape[1] >= 3 else np.column_stack([points, np.zeros(len(points))])
    k = int(min(max(k, 3), len(p)))
    tree = cKDTree(p)
    query = p if only is None else p[only]
    out = np.zeros((len(query), 3))
    for s in range(0, len(query), _BLOCK):
        _, idx = tree.query(query[s : s + _BLOCK], k=k)
        nb = p[np.asarray(idx).reshape(-1, k)]
        centred = nb - nb.mean(axis=1, keepdims=True)
        cov = np.einsum("nki,nkj->nij", centred, centred)
        _, vecs = np.linalg.eigh(cov)
        out[s : s + len(vecs)] = vecs[:, :, 0]
    return unit_rows(out)[0]


def orient_globally(new: NDArray[np.float64], old: NDArray[Any] | None) -> NDArray[np.float64]:
    """Flip all of ``new`` if it disagrees with ``old`` on most rows (mesh normals)."""
    if old is None:
        return new
    dots = np.einsum("ij,ij->i", new, np.asarray(old, dtype=np.float64))
    return -new if np.count_nonzero(dots < 0) > np.count_nonzero(dots > 0) else new


def orient_pointwise(new: NDArray[np.float64], old: NDArray[Any] | None) -> NDArray[np.float64]:
    """Flip each row of ``new`` that points away from ``old`` (cloud normals)."""
    if old is None:
        return new
    dots = np.einsum("ij,ij->i", new, np.asarray(old, dtype=np.float64))
    return np.where((dots < 0)[:, None], -new, new)
