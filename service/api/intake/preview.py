"""Display arrays of a document for the web page's viewer (``POST /v1/info?preview=true``).

Positions as little-endian float32 relative to ``origin`` (the bounding-box centre, so that large
coordinates keep their precision), faces and line segments as uint32, each base64-encoded, all
in the file's vertex order (the order of a job's result). Runs in the request's worker process
(numpy only), like the rest of :mod:`service.api.intake.ingest`.
"""

from __future__ import annotations

import base64
from typing import Any

import numpy as np
from numpy.typing import NDArray

from service.io import GeometryDocument
from service.io._shared.plain import WriteOptions, plain_document

__all__ = ["preview_dict"]


def _b64(array: NDArray[Any]) -> str:
    return base64.b64encode(np.ascontiguousarray(array).tobytes()).decode("ascii")


def preview_dict(document: GeometryDocument) -> dict[str, Any]:
    """``{origin, n_points, dimension, positions, faces, segments}`` (see the module docstring)."""
    plain = plain_document(document, options=WriteOptions(normals="drop"))
    points = plain.points
    n, dim = points.shape
    xyz = np.zeros((n, 3), dtype=np.float64)
    xyz[:, : min(dim, 3)] = points[:, :3]
    origin = (xyz.min(axis=0) + xyz.max(axis=0)) / 2 if n else np.zeros(3)
    faces = plain.faces
    segments = plain.edges()
    return {
        "origin": origin.tolist(),
        "n_points": n,
        "dimension": dim,
        "positions": _b64((xyz - origin).astype("<f4")),
        "faces": None if faces is None else _b64(faces.astype("<u4")),
        "segments": None if segments is None else _b64(segments.astype("<u4")),
    }
