"""Connectivity helpers shared by the readers: index checks, fan triangulation, clean-up.

Rules (the same for every format):

* An index outside the vertex list is a :class:`~service.io.errors.FormatError` naming the
  element and the vertex count.
* Polygons are fan-triangulated: ``(v0, v1, v2), (v0, v2, v3), ...``. Polygons with fewer than
  three vertices are dropped.
* Faces and edges that repeat a vertex (common in scanner output) are dropped, and the number
  dropped is recorded in the document's notes; the engine rejects such elements.
* Polylines: consecutive repeated indices are collapsed; a last index equal to the first closes
  the polyline (stored once, ``closed=True``); polylines left with fewer than two vertices are
  dropped.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from service.io.document import Polyline
from service.io.errors import FormatError

__all__ = [
    "as_indices",
    "check_indices",
    "drop_repeating",
    "edge_array",
    "fan_triangulate",
    "normalize_polyline",
]


def as_indices(values: NDArray[Any], *, what: str, fmt: str) -> NDArray[Any]:
    """Index values (integers, or floats holding integers) as int64.

    Raises
    ------
    FormatError
        For fractional, non-finite or absurdly large values.
    """
    if values.dtype.kind == "f":
        ok = np.isfinite(values) & (np.abs(values) < 2.0**53)
        ok &= values == np.round(np.where(ok, values, 0.0))
        if not np.all(ok):
            bad = float(values.reshape(-1)[~ok.reshape(-1)][0])
            raise FormatError(f"{what} indices must be integers, found {bad!r}", fmt=fmt)
        return values.astype(np.int64)
    if values.dtype.kind == "u" and values.dtype.itemsize == 8:
        return values.astype(np.int64)  # beyond int64 wraps negative: caught as out of range
    return values  # integers stay in their own (compact) dtype; Geometry makes them int64


def check_indices(
    flat: NDArray[np.int64],
    n: int,
    *,
    what: str,
    fmt: str,
    counts: NDArray[np.int64] | None = None,
    lines: NDArray[np.int64] | None = None,
    base: int = 0,
    start: int = 0,
) -> None:
    """Raise FormatError if an index lies outside ``[0, n)``.

    Parameters
    ----------
    flat : ndarray of int
        All indices of the elements, concatenated (0-based).
    n : int
        Number of vertices.
    what : str
        Element name for the message (``"face"``, ``"edge"``, ``"polyline"``).
    fmt : str
        Format name for the error.
    counts : ndarray of int, optional
        Number of indices of each element (default: one index per element).
    lines : ndarray of int, optional
        1-based line number of each element (text formats): the message then names the line.
    base : int
        Added to vertex indices in the message (1 for OBJ, whose indices are 1-based).
    start : int
        Number of the first element in the message (when checking one element of many).
    """
    bad = (flat < 0) | (flat >= n)
    if not bad.any():
        return
    pos = int(np.flatnonzero(bad)[0])
    elem = pos if counts is None else int(np.searchsorted(np.cumsum(counts), pos, side="right"))
    vertex = int(flat.reshape(-1)[pos]) + base
    if lines is not None:
        line = int(lines[elem])
        raise FormatError(
            f"line {line}: {what} refers to vertex {vertex} but the file has {n} vertices",
            fmt=fmt,
            line=line,
        )
    raise FormatError(
        f"{what} {elem + start} refers to vertex {vertex} but the file has {n} vertices", fmt=fmt
    )


_BLOCK = 1 << 16


def fan_triangulate(
    flat: NDArray[np.int64], counts: NDArray[np.int64]
) -> tuple[NDArray[np.int64], int]:
    """Fan-triangulate polygons given as concatenated indices and per-polygon counts.

    Returns
    -------
    triangles : ndarray of int, shape (m, 3)
    n_small : int
        Number of polygons with fewer than three vertices (dropped).
    """
    counts = np.asarray(counts)
    flat = np.asarray(flat)
    if counts.size == 0:
        return np.zeros((0, 3), dtype=np.int64), 0
    if counts.min() == counts.max() == 3:
        return flat.reshape(-1, 3), 0
    n_small = sum(
        int(np.count_nonzero(counts[a : a + _BLOCK] < 3)) for a in range(0, counts.size, _BLOCK)
    )
    flat = flat.reshape(-1)
    total = sum(
        int(np.clip(counts[a : a + _BLOCK].astype(np.int64) - 2, 0, None).sum())
        for a in range(0, counts.size, _BLOCK)
    )
    tris = np.empty((total, 3), dtype=flat.dtype)
    offset = at = 0
    for a in range(0, counts.size, _BLOCK):  # blocks: temporaries stay O(block)
        c = counts[a : a + _BLOCK].astype(np.int64)
        starts = offset + np.concatenate([[0], np.cumsum(c)[:-1]])
        offset += int(c.sum())
        keep = c >= 3
        if not keep.any():
            continue
        c, starts = c[keep], starts[keep]
        ntri = c - 2
        first_tri = np.concatenate([[0], np.cumsum(ntri)[:-1]])
        j = np.arange(int(ntri.sum())) - np.repeat(first_tri, ntri)
        s = np.repeat(starts, ntri)
        k = s.size
        tris[at : at + k, 0] = flat[s]
        tris[at : at + k, 1] = flat[s + j + 1]
        tris[at : at + k, 2] = flat[s + j + 2]
        at += k
    return tris, n_small


def drop_repeating(elements: NDArray[np.int64]) -> tuple[NDArray[np.int64], int]:
    """Drop rows that repeat a vertex index; return the kept rows and how many were dropped."""
    if elements.size == 0:
        return elements, 0
    k = elements.shape[1]
    if k <= 4:  # pairwise comparisons: no sorted copy of the elements
        rep = np.zeros(len(elements), dtype=bool)
        for i in range(k):
            for j in range(i + 1, k):
                rep |= elements[:, i] == elements[:, j]
    else:
        srt = np.sort(elements, axis=1)
        rep = (srt[:, 1:] == srt[:, :-1]).any(axis=1)
    n_rep = int(np.count_nonzero(rep))
    return (elements[~rep] if n_rep else elements), n_rep


def normalize_polyline(indices: NDArray[np.int64], closed: bool = False) -> Polyline | None:
    """Collapse consecutive repeats, detect closure; ``None`` if fewer than two vertices remain."""
    idx = np.asarray(indices, dtype=np.int64).reshape(-1)
    if idx.size > 1:
        keep = np.concatenate([[True], idx[1:] != idx[:-1]])
        idx = idx[keep]
    if idx.size >= 2 and idx[0] == idx[-1]:
        idx = idx[:-1]
        closed = True
    if idx.size < 2:
        return None
    return Polyline(idx, closed=bool(closed) and idx.size >= 3)


def edge_array(
    standalone: NDArray[np.int64] | None, polylines: Sequence[Polyline]
) -> NDArray[np.int64] | None:
    """The engine's edges: the standalone ones, then each polyline's (``None``: no edges)."""
    parts = ([standalone] if standalone is not None and len(standalone) else []) + [
        p.edges() for p in polylines
    ]
    return np.concatenate(parts) if parts else None
