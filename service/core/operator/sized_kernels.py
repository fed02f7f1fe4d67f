"""The neighbourhood builds' kernels at the input's size: NumPy below :data:`COMPILED_FROM`.

:mod:`.kernels` holds the numba versions. Importing numba (with llvmlite) costs about 0.35 s CPU
and 90 MB before a kernel runs, more than a whole 200-point run needs (issue 30 item 4), so a
small input takes the NumPy versions here: the same outputs, bit for bit (integer patterns;
the covariances summed in the compiled loop's order; the hull march with the compiled one's
candidates and tie rules, vectorised over the points as before issue 22). From
:data:`COMPILED_FROM` points, or once :mod:`.kernels` is loaded anyway, the compiled kernel
runs. The callers import their kernel from here with the signature of :mod:`.kernels`.
"""

from __future__ import annotations

import sys

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "COMPILED_FROM",
    "mesh_rings",
    "neighbourhood_covariances",
    "polar_hull_fans",
    "rows_from_pairs",
]

Ints = NDArray[np.int64]
Array = NDArray[np.float64]

#: From this many points the compiled kernels are worth their import (the grid k-NN's
#: threshold, :data:`service.core.operator.knn.GRID_FROM`, is the same size).
COMPILED_FROM = 50_000


def _compiled(n: int) -> bool:
    return n >= COMPILED_FROM or "service.core.operator.kernels" in sys.modules


def rows_from_pairs(i: Ints, j: Ints, n: int) -> tuple[Ints, Ints, Ints]:
    """CSR ``(indptr, indices, multiplicity)`` of the distinct pairs ``(i, j)``, rows sorted."""
    if _compiled(n):
        from service.core.operator import kernels

        return kernels.rows_from_pairs(i, j, n)  # type: ignore[no-any-return]
    key = np.sort(i.astype(np.int64) * n + j)  # n < COMPILED_FROM: n * n fits in int64
    new = np.ones(key.size, dtype=bool)
    new[1:] = key[1:] != key[:-1]
    starts = np.flatnonzero(new)
    uniq = key[starts]
    mult = np.diff(np.append(starts, key.size)).astype(np.int64)
    rows = uniq // n
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(rows, minlength=n), out=indptr[1:])
    return indptr, (uniq - rows * n).astype(np.int64), mult


def mesh_rings(faces: Ints, n: int) -> tuple[Ints, Ints, NDArray[np.bool_]]:
    """1-ring CSR ``(indptr, indices)`` of a triangle mesh and its boundary vertices.

    ``faces`` must hold distinct triangles (any winding); see :func:`.kernels.mesh_rings`.
    """
    if _compiled(n):
        from service.core.operator import kernels

        return kernels.mesh_rings(faces, n)  # type: ignore[no-any-return]
    f = np.asarray(faces, dtype=np.int64)
    i = np.concatenate([f[:, 0], f[:, 1], f[:, 2]] * 2)
    j = np.concatenate([f[:, 1], f[:, 2], f[:, 0], f[:, 2], f[:, 0], f[:, 1]])
    indptr, cols, mult = rows_from_pairs(i, j, n)
    row = np.repeat(np.arange(n, dtype=np.int64), np.diff(indptr))
    once = mult == np.where(cols == row, 2, 1)  # an edge of exactly one face
    boundary = np.zeros(n, dtype=np.bool_)
    boundary[row[once]] = True
    boundary[cols[once]] = True
    return indptr, cols, boundary


def neighbourhood_covariances(X: Array, idx: Ints) -> Array:
    """``sum_a (x_a - mean)(x_a - mean)^T`` over the rows ``idx[p]`` of ``X``, per point ``p``.

    Summed over ``a`` in the compiled kernel's order, so the result is the same to the bit.
    """
    if _compiled(idx.shape[0]):
        from service.core.operator import kernels

        return kernels.neighbourhood_covariances(X, idx)  # type: ignore[no-any-return]
    n, k = idx.shape
    s = X.shape[1]
    mu = np.zeros((n, s))
    for a in range(k):
        mu += X[idx[:, a]]
    mu /= k
    out = np.zeros((n, s, s))
    for a in range(k):
        d = X[idx[:, a]] - mu
        out += d[:, :, None] * d[:, None, :]
    return out


def polar_hull_fans(q: Array) -> tuple[Ints, Ints, NDArray[np.bool_]]:
    """Delaunay 1-rings of the origin among planar neighbours (:func:`.kernels.polar_hull_fans`).

    The gift-wrapping march vectorised over the points: the same candidates (the polar points
    ``2 q / |q|^2`` and the origin), start (the farthest), turn keys (smallest turn rounded to
    12 decimals, the farthest among collinear ones) and stop rules as the compiled kernel.
    """
    if _compiled(q.shape[0]):
        from service.core.operator import kernels

        return kernels.polar_hull_fans(q)  # type: ignore[no-any-return]
    n, m, _ = q.shape
    r2 = q[..., 0] * q[..., 0] + q[..., 1] * q[..., 1]
    valid = r2 > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        a = np.where(valid[..., None], 2.0 * q / r2[..., None], 0.0)
    cand = np.concatenate([a, np.zeros((n, 1, 2))], axis=1)  # slot m: the origin
    cvalid = np.concatenate([valid, np.ones((n, 1), dtype=bool)], axis=1)
    norms = np.where(cvalid, cand[..., 0] * cand[..., 0] + cand[..., 1] * cand[..., 1], -1.0)
    norms[:, m] = -1.0
    start = np.argmax(norms, axis=1)
    has_any: NDArray[np.bool_] = np.asarray(valid.any(axis=1))
    order = _march(cand, cvalid, start, has_any)
    return _fans(order, m)


def _march(cand: Array, cvalid: NDArray[np.bool_], start: Ints, active: NDArray[np.bool_]) -> Ints:
    """Hull slots of each point in march order (``-1`` padded), from ``start``."""
    n, m1, _ = cand.shape
    rows = np.arange(n)
    cur = start.copy()
    first = cand[rows, start]
    direction = np.column_stack([-first[:, 1], first[:, 0]])  # CCW tangent at the start
    on_hull = np.zeros((n, m1), dtype=bool)
    on_hull[rows[active], start[active]] = True
    order = np.full((n, m1), -1, dtype=np.int64)
    order[:, 0] = np.where(active, start, -1)
    active = active.copy()
    for step in range(1, m1):
        if not active.any():
            break
        ar = rows[active]
        v = cand[ar] - cand[ar, cur[ar]][:, None, :]
        d0, d1 = direction[ar, 0][:, None], direction[ar, 1][:, None]
        ang = np.mod(
            np.arctan2(d0 * v[..., 1] - d1 * v[..., 0], d0 * v[..., 0] + d1 * v[..., 1]),
            2.0 * np.pi,
        )
        dist = v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1]
        scale = np.maximum(dist.max(axis=1, keepdims=True), 1e-300)
        ang = np.where(~cvalid[ar] | (dist <= 1e-24 * scale), np.inf, ang)
        key = np.rint(ang * 1e12) / 1e12 - dist / scale * 1e-13
        nxt = np.argmin(key, axis=1)
        done = (nxt == start[ar]) | on_hull[ar, nxt] | ~np.isfinite(ang[np.arange(ar.size), nxt])
        go, to = ar[~done], nxt[~done]
        on_hull[go, to] = True
        order[go, step] = to
        direction[go] = cand[go, to] - cand[go, cur[go]]
        cur[go] = to
        active[ar[done]] = False
    return order


def _fans(order: Ints, m: int) -> tuple[Ints, Ints, NDArray[np.bool_]]:
    """Fans from the march: open ones (the origin on the hull) rotated to start after it."""
    n = order.shape[0]
    open_fan = (order == m).any(axis=1)
    lengths = (order >= 0).sum(axis=1)
    fans = np.full((n, m), -1, dtype=np.int64)
    count = np.zeros(n, dtype=np.int64)
    for length in np.unique(lengths[lengths > 0]):
        for with_origin in (False, True):
            sel = np.flatnonzero((lengths == length) & (open_fan == with_origin))
            if sel.size == 0:
                continue
            o = order[sel, :length]
            if with_origin:
                shift = np.argmax(o == m, axis=1) + 1
                roll = (np.arange(length)[None, :] + shift[:, None]) % length
                o = np.take_along_axis(o, roll, axis=1)[:, : length - 1]
            fans[sel, : o.shape[1]] = o
            count[sel] = o.shape[1]
    return fans, count, open_fan
