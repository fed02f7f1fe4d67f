"""Texture coordinates of a mesh read from OBJ, for the other formats that hold them.

OBJ gives every face corner its own ``vt`` index (``f v/vt``), so one vertex can have several
UVs (at the seams of the texture atlas: spot.obj has 2930 vertices and 3225 ``vt``). glTF holds
one UV per vertex: the mesh is split into one vertex per distinct (vertex, ``vt``) pair, as
trimesh and Blender do on import, positions and colours copied from the vertex. PLY keeps the
vertices and gives each face its corners' UVs (``property list uchar float texcoord``, as
MeshLab writes; trimesh reads it).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from service.io._shared.elements import fan_triangulate

__all__ = ["corner_uvs", "keeps_uv", "split_at_seams", "texture_ready"]

#: Formats that hold the UVs of another format's mesh: glTF one UV per vertex (split at seams),
#: PLY per face corner (MeshLab's face ``texcoord`` list, which trimesh reads).
UV_FORMATS = frozenset({"glb", "ply"})


def texture_ready(doc: Any) -> bool:
    """Whether ``doc`` (a document or a plain document's source) has a UV at every face corner
    and every vertex in a face, so a per-vertex-UV mesh holds all of it."""
    uv = getattr(doc.layout, "uv", None)
    faces = doc.geometry.faces
    if uv is None or faces is None or not len(faces) or doc.weld is not None:
        return False
    used = np.zeros(doc.geometry.n, dtype=bool)
    used[np.asarray(faces).reshape(-1)] = True
    return bool(used.all())


def keeps_uv(doc: Any, fmt: str) -> bool:
    """Whether writing ``doc`` as ``fmt`` (another format) keeps its texture coordinates: PLY,
    and glTF without vertex colours (trimesh exports one of the two), for a complete texture."""
    coloured = fmt == "glb" and all(c in doc.attributes for c in ("red", "green", "blue"))
    return fmt in UV_FORMATS and texture_ready(doc) and not coloured


def _vt_values(data: bytes, spans: NDArray[np.int64]) -> NDArray[np.float64]:
    """``u v`` of every ``vt u [v [w]]`` line (``v`` = 0 when absent)."""
    out = np.zeros((len(spans), 2))
    for i, (a, b) in enumerate(spans.tolist()):
        values = data[a:b].split()[1:3]
        out[i, : len(values)] = [float(x) for x in values]
    return out


def corner_uvs(plain: Any, fmt: str) -> tuple[NDArray[np.int64], NDArray[np.float64]] | None:
    """Per triangle corner, its ``vt`` index (shaped like ``plain.faces``), and the ``vt`` values;
    ``None`` when ``fmt`` keeps no texture coordinates of this input (:func:`keeps_uv`)."""
    if plain.faces is None or not keeps_uv(plain.source, fmt):
        return None
    corner_vt, counts, spans = plain.layout.uv
    tri_vt, _ = fan_triangulate(corner_vt, counts)
    if tri_vt.shape != np.shape(plain.faces):
        return None
    return np.asarray(tri_vt, dtype=np.int64), _vt_values(plain.layout.data, spans)


def split_at_seams(
    faces: NDArray[np.int64], tri_vt: NDArray[np.int64]
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """One vertex per distinct (vertex, vt) pair: its vertex, its vt, and the new faces."""
    pairs = np.column_stack([np.asarray(faces).reshape(-1), tri_vt.reshape(-1)])
    unique, inverse = np.unique(pairs, axis=0, return_inverse=True)
    return unique[:, 0], unique[:, 1], np.asarray(inverse).reshape(-1, 3)
