"""Compiled kernels of the neighbourhood builds (numba; imported lazily by their callers).

* :func:`rows_from_pairs` — the CSR pattern of directed pairs ``(i, j)`` with each distinct
  pair's multiplicity: a counting sort on ``i`` and an insertion sort of each (short) row, so
  the cost is linear in the number of pairs (no global sort of ``i n + j`` keys).
* :func:`has_duplicate_faces` — whether two triangles have the same vertex set: a counting
  sort of the faces on their smallest vertex and a comparison within each (short) bucket, so
  the common case of no duplicates costs one linear pass (issue 30: the two global sorts of
  ``unique_faces`` took 0.18 s at 1M vertices);
* :func:`mesh_rings` — the same for the 1-rings of a triangle mesh straight from its faces (the
  six directed edges of every face), with the boundary flags: an undirected edge used by
  exactly one face appears exactly once in each of its end points' rows (twice for a
  degenerate self-edge ``(a, a)``, which contributes both directions to one row).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = [
    "has_duplicate_faces",
    "mesh_rings",
    "neighbourhood_covariances",
    "polar_hull_fans",
    "rows_from_pairs",
]


@njit(cache=True)
def _sort_rows(
    indptr: NDArray[np.int64], cols: NDArray[np.int64], n: int
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:  # pragma: no cover
    """Sort each row of a bucketed pattern, merge duplicates, count them."""
    out_ptr = np.zeros(n + 1, dtype=np.int64)
    out = np.empty(cols.size, dtype=np.int64)
    mult = np.empty(cols.size, dtype=np.int64)
    pos = 0
    for r in range(n):
        a, b = indptr[r], indptr[r + 1]
        for p in range(a + 1, b):  # insertion sort: rows hold ~12 entries
            v = cols[p]
            q = p - 1
            while q >= a and cols[q] > v:
                cols[q + 1] = cols[q]
                q -= 1
            cols[q + 1] = v
        p = a
        while p < b:
            v = cols[p]
            c = 0
            while p < b and cols[p] == v:
                c += 1
                p += 1
            out[pos] = v
            mult[pos] = c
            pos += 1
        out_ptr[r + 1] = pos
    return out_ptr, out[:pos].copy(), mult[:pos].copy()


@njit(cache=True)
def rows_from_pairs(
    i: NDArray[np.int64], j: NDArray[np.int64], n: int
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:  # pragma: no cover
    """CSR ``(indptr, indices, multiplicity)`` of the distinct pairs ``(i, j)``, rows sorted."""
    indptr = np.zeros(n + 1, dtype=np.int64)
    for p in range(i.size):
        indptr[i[p] + 1] += 1
    for r in range(n):
        indptr[r + 1] += indptr[r]
    fill = indptr[:-1].copy()
    cols = np.empty(i.size, dtype=np.int64)
    for p in range(i.size):
        cols[fill[i[p]]] = j[p]
        fill[i[p]] += 1
    return _sort_rows(indptr, cols, n)


@njit(cache=True)
def has_duplicate_faces(faces: NDArray[np.int64], n: int) -> bool:  # pragma: no cover
    """Whether two rows of ``faces`` (triangles on ``n`` points) hold the same vertex set."""
    m = faces.shape[0]
    lo = np.empty(m, dtype=np.int64)
    key = np.empty(m, dtype=np.int64)  # the two larger vertices, y n + z (fits: n < 3e9)
    start = np.zeros(n + 1, dtype=np.int64)
    for f in range(m):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        if a > b:
            a, b = b, a
        if b > c:
            b, c = c, b
        if a > b:
            a, b = b, a
        lo[f] = a
        key[f] = b * n + c
        start[a + 1] += 1
    for v in range(n):
        start[v + 1] += start[v]
    fill = start[:-1].copy()
    bucket = np.empty(m, dtype=np.int64)
    for f in range(m):
        bucket[fill[lo[f]]] = key[f]
        fill[lo[f]] += 1
    for v in range(n):
        a, b = start[v], start[v + 1]
        if b - a > 16:  # a hub: sort its bucket
            keys = np.sort(bucket[a:b])
            for p in range(keys.size - 1):
                if keys[p] == keys[p + 1]:
                    return True
            continue
        for p in range(a, b):  # a few faces: compare all pairs
            for q in range(p + 1, b):
                if bucket[p] == bucket[q]:
                    return True
    return False


@njit(cache=True)
def mesh_rings(
    faces: NDArray[np.int64], n: int
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.bool_]]:  # pragma: no cover
    """1-ring CSR ``(indptr, indices)`` of a triangle mesh and its boundary vertices.

    ``faces`` must hold distinct triangles (any winding).
    """
    indptr = np.zeros(n + 1, dtype=np.int64)
    m = faces.shape[0]
    for f in range(m):
        for c in range(3):
            indptr[faces[f, c] + 1] += 2
    for r in range(n):
        indptr[r + 1] += indptr[r]
    fill = indptr[:-1].copy()
    cols = np.empty(indptr[n], dtype=np.int64)
    for f in range(m):
        for c in range(3):
            v = faces[f, c]
            cols[fill[v]] = faces[f, (c + 1) % 3]
            cols[fill[v] + 1] = faces[f, (c + 2) % 3]
            fill[v] += 2
    out_ptr, out, mult = _sort_rows(indptr, cols, n)
    boundary = np.zeros(n, dtype=np.bool_)
    for r in range(n):
        for p in range(out_ptr[r], out_ptr[r + 1]):
            v = out[p]
            if mult[p] == (2 if v == r else 1):
                boundary[r] = True
                boundary[v] = True
    return out_ptr, out, boundary


@njit(cache=True)
def neighbourhood_covariances(
    X: NDArray[np.float64], idx: NDArray[np.int64]
) -> NDArray[np.float64]:  # pragma: no cover
    """``sum_a (x_a - mean)(x_a - mean)^T`` over the rows ``idx[p]`` of ``X``, per point ``p``
    (shape ``(n, s, s)``), without the ``(n, k, s)`` gather."""
    n, k = idx.shape
    s = X.shape[1]
    out = np.zeros((n, s, s))
    mu = np.zeros(s)
    for p in range(n):
        mu[:] = 0.0
        for a in range(k):
            for c in range(s):
                mu[c] += X[idx[p, a], c]
        mu /= k
        for a in range(k):
            q = idx[p, a]
            for c in range(s):
                dc = X[q, c] - mu[c]
                for e in range(c, s):
                    out[p, c, e] += dc * (X[q, e] - mu[e])
        for c in range(s):
            for e in range(c + 1, s):
                out[p, e, c] = out[p, c, e]
    return out


@njit(cache=True)
def polar_hull_fans(
    q: NDArray[np.float64],
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.bool_]]:  # pragma: no cover
    """Delaunay 1-rings of the origin among planar neighbours, one point at a time.

    The gift-wrapping march of ``delaunay._polar_hull_fans`` (same candidates, same tie rules:
    smallest turn rounded to 12 decimals, the farthest among collinear ones), compiled: no
    ``(n, m)`` temporaries per step. Returns the fans (``-1`` padded, rotated to start after
    the origin for open fans), their sizes and the open-fan flags.
    """
    n, m, _ = q.shape
    fans = np.full((n, m), -1, dtype=np.int64)
    count = np.zeros(n, dtype=np.int64)
    open_fan = np.zeros(n, dtype=np.bool_)
    cand = np.zeros((m + 1, 2))
    cvalid = np.zeros(m + 1, dtype=np.bool_)
    on_hull = np.zeros(m + 1, dtype=np.bool_)
    order = np.empty(m + 1, dtype=np.int64)
    key = np.empty(m + 1)
    ang = np.empty(m + 1)
    dist = np.empty(m + 1)
    two_pi = 2.0 * np.pi
    for p in range(n):
        start, best, any_valid = 0, -1.0, False
        for a in range(m):
            r2 = q[p, a, 0] * q[p, a, 0] + q[p, a, 1] * q[p, a, 1]
            cvalid[a] = r2 > 0
            if r2 > 0:
                any_valid = True
                cand[a, 0], cand[a, 1] = 2.0 * q[p, a, 0] / r2, 2.0 * q[p, a, 1] / r2
                nrm = cand[a, 0] * cand[a, 0] + cand[a, 1] * cand[a, 1]
                if nrm > best:
                    best, start = nrm, a
            else:
                cand[a, 0], cand[a, 1] = 0.0, 0.0
        cand[m, 0], cand[m, 1] = 0.0, 0.0
        cvalid[m] = True
        if not any_valid:
            continue
        on_hull[:] = False
        on_hull[start] = True
        order[0] = start
        length = 1
        cur = start
        d0, d1 = -cand[start, 1], cand[start, 0]
        for _step in range(1, m + 1):
            scale = 0.0
            for a in range(m + 1):
                v0, v1 = cand[a, 0] - cand[cur, 0], cand[a, 1] - cand[cur, 1]
                dist[a] = v0 * v0 + v1 * v1
                scale = max(scale, dist[a])
                x = np.arctan2(d0 * v1 - d1 * v0, d0 * v0 + d1 * v1)
                r = np.fmod(x, two_pi)
                if r != 0 and r < 0:
                    r += two_pi
                ang[a] = r
            scale = max(scale, 1e-300)
            nxt = 0
            for a in range(m + 1):
                if not cvalid[a] or dist[a] <= 1e-24 * scale:
                    ang[a] = np.inf
                key[a] = np.rint(ang[a] * 1e12) / 1e12 - dist[a] / scale * 1e-13
                if key[a] < key[nxt]:
                    nxt = a
            if nxt == start or on_hull[nxt] or not np.isfinite(ang[nxt]):
                break
            on_hull[nxt] = True
            order[length] = nxt
            length += 1
            d0, d1 = cand[nxt, 0] - cand[cur, 0], cand[nxt, 1] - cand[cur, 1]
            cur = nxt
        if on_hull[m]:
            open_fan[p] = True
            shift = 0
            for a in range(length):
                if order[a] == m:
                    shift = a + 1
            for a in range(length - 1):
                fans[p, a] = order[(a + shift) % length]
            count[p] = length - 1
        else:
            for a in range(length):
                fans[p, a] = order[a]
            count[p] = length
    return fans, count, open_fan
