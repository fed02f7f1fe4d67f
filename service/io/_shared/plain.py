"""Un-weld once at write time: the plain document every writer receives.

:func:`plain_document` expands a (possibly welded) :class:`~service.io.document.GeometryDocument`
and the smoothed points back to the file's vertices, and recomputes (or drops) the normals, once.
Writers then see one vertex numbering (the file's), plain arrays, and the options.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from service.io._shared.normals import (
    cloud_normals,
    mesh_normals,
    orient_globally,
    orient_pointwise,
    unit_rows,
)
from service.io._shared.numfmt import F32, default_spec, fine_enough
from service.io.document import GeometryDocument, Polyline

__all__ = ["NormalsMode", "PlainDocument", "PrecisionMode", "WriteOptions", "plain_document"]

NormalsMode = Literal["recompute", "drop"]
PrecisionMode = Literal["input", "float32", "float64"]


@dataclass(frozen=True)
class WriteOptions:
    """Options every writer understands.

    Attributes
    ----------
    normals : {"recompute", "drop"}
        Normals of the input are recomputed from the written geometry, or left out.
    precision : {"input", "float32", "float64"}
        Coordinates as the input stored them (dtype, or digits for text formats), or forced.
    ply_ascii : bool or None
        PLY only: ASCII (True), binary (False), or the input's encoding (None; binary for
        inputs of other formats).
    """

    normals: NormalsMode = "recompute"
    precision: PrecisionMode = "input"
    ply_ascii: bool | None = None

    def __post_init__(self) -> None:
        if self.normals not in ("recompute", "drop"):
            raise ValueError(f"normals must be 'recompute' or 'drop', got {self.normals!r}")
        if self.precision not in ("input", "float32", "float64"):
            raise ValueError(
                f"precision must be 'input', 'float32' or 'float64', got {self.precision!r}"
            )


@dataclass(frozen=True, eq=False)
class PlainDocument:
    """A document in the file's vertex numbering, ready to write (no weld map).

    ``points`` are the positions to write; ``normals`` the recomputed unit normals (the input's
    own when no new points were given; ``None`` if the input had none or they are dropped); the
    rest as in the source document.
    """

    points: NDArray[np.float64]
    faces: NDArray[np.int64] | None
    standalone_edges: NDArray[np.int64] | None
    polylines: list[Polyline]
    weights: NDArray[np.float64] | None
    fixed: NDArray[np.int64] | None
    attributes: dict[str, NDArray[Any]]
    normals: NDArray[np.floating[Any]] | None
    source: GeometryDocument
    options: WriteOptions = field(default_factory=WriteOptions)
    moved: bool = True
    georef: Any = None  # service.io._shared.georef.Georef of geographic input written planar

    @property
    def n(self) -> int:
        """Number of vertices written."""
        return int(self.points.shape[0])

    @property
    def dim(self) -> int:
        """Coordinates per point."""
        return int(self.points.shape[1])

    @property
    def comments(self) -> list[str]:
        """Header comments of the input (and the frame of georeferenced coordinates)."""
        if self.georef is None:
            return self.source.comments
        return [*self.source.comments, *self.georef.lines()]

    @property
    def layout(self) -> object | None:
        """The source's format-specific layout (writers check its type)."""
        return self.source.layout

    def edges(self) -> NDArray[np.int64] | None:
        """All edges (standalone, then polyline edges)."""
        parts = [p.edges() for p in self.polylines]
        if self.standalone_edges is not None:
            parts.insert(0, self.standalone_edges)
        parts = [p for p in parts if len(p)]
        return np.concatenate(parts).astype(np.int64) if parts else None

    def coordinate_dtype(self) -> np.dtype[Any]:
        """Float dtype of written coordinates (binary formats)."""
        mode = self.options.precision
        if mode != "input":
            return np.dtype(mode)
        stored = np.dtype(self.source.precision.dtype)
        return stored if stored.kind == "f" else np.dtype(np.float64)

    def coordinate_specs(self) -> tuple[str, ...]:
        """Printf spec per coordinate (text formats; see :mod:`service.io._shared.numfmt`)."""
        mode = self.options.precision
        if mode == "float32":
            return (F32,) * self.dim
        if mode == "float64":
            return ("%r",) * self.dim
        text = self.source.precision.text
        if text is None or len(text) != self.dim:
            return (default_spec(self.coordinate_dtype()),) * self.dim
        pts = self.points
        extent = float(np.max(np.ptp(pts, axis=0))) if len(pts) else 0.0
        return tuple(fine_enough(spec, pts[:, j], extent) for j, spec in enumerate(text))

    def attribute_spec(self, name: str) -> str:
        """Printf spec of an attribute column (the input's digits when it was text)."""
        spec = self.source.precision.attribute_text.get(name)
        return spec if spec is not None else default_spec(self.attributes[name].dtype)


def _nearest(
    points: NDArray[np.float64], missing: NDArray[np.bool_], lost: NDArray[np.int64]
) -> NDArray[np.int64]:
    """For each point in ``lost``, the nearest point that is not ``missing``."""
    from scipy.spatial import cKDTree

    have = np.flatnonzero(~missing)
    if have.size == 0:
        return lost
    _, j = cKDTree(points[have]).query(points[lost], k=1)
    return np.asarray(have[np.asarray(j)], dtype=np.int64)


def _normals(
    doc: GeometryDocument, points: NDArray[np.float64], faces: NDArray[np.int64] | None
) -> NDArray[np.float64] | None:
    old = doc.normals
    if old is None or points.shape[1] not in (2, 3):
        return None
    if faces is not None and len(faces):
        new = mesh_normals(points, faces)
        new = orient_globally(new, old)
        missing = ~np.any(new != 0, axis=1)
        if missing.any():  # vertices in no face keep their input normal, else a PCA one
            kept, ok = unit_rows(np.asarray(old, dtype=np.float64)[missing])
            if not ok.all():  # no input normal either: PCA, oriented like the nearest vertex
                lost = np.flatnonzero(missing)[~ok]
                kept[~ok] = orient_pointwise(
                    cloud_normals(points, only=lost), new[_nearest(points, missing, lost)]
                )
            new[missing] = kept
        return new
    return orient_pointwise(cloud_normals(points), old)


def plain_document(
    doc: GeometryDocument, points: ArrayLike | None = None, options: WriteOptions | None = None
) -> PlainDocument:
    """Expand ``doc`` (with ``points``, default its own) to the file's vertices, once.

    Raises
    ------
    ValueError
        If ``points`` does not have the shape of ``doc.geometry.points``.
    """
    options = options or WriteOptions()
    pts = doc.checked_points(points)
    g = doc.geometry
    if doc.weld is not None:
        w = doc.weld
        pts = pts[w.index]
        faces, edges, polylines, weights, fixed = (
            w.faces,
            w.standalone_edges,
            w.polylines,
            w.weights,
            w.fixed,
        )
    else:
        faces, edges, polylines = g.faces, doc.standalone_edges, doc.polylines
        weights, fixed = g.weights, g.fixed
    normals: NDArray[np.floating[Any]] | None = None
    if options.normals == "recompute":
        normals = _normals(doc, pts, faces) if points is not None else doc.normals
    return PlainDocument(
        points=pts,
        faces=faces,
        standalone_edges=edges,
        polylines=list(polylines),
        weights=weights,
        fixed=fixed,
        attributes=dict(doc.attributes),
        normals=normals,
        source=doc,
        options=options,
        moved=points is not None,
    )
