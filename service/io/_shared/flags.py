"""Outliers in the output (issue 31): a flag where the format holds one, or rows dropped.

The engine reports its outliers (``SmoothResult.outliers``) and what it did with them
(``outlier_mode``): ``"flag"`` kept them at their input positions, ``"drop"`` asks for a cloud
without them. :func:`with_outliers` turns that into the document written:

* flag: LAS/LAZ ``classification`` = 7 (ASPRS "low point (noise)", as PDAL's
  ``filters.outlier``), the other points' classes unchanged; PLY and PCD a vertex attribute
  ``outlier`` (``uchar``/``U 1``: 1 outlier, 0 not); other formats (XYZ, OBJ, E57, JSON ...)
  hold no flag: the report's ``outliers`` indices are the record.
* drop: the rows of a point cloud removed, every per-vertex array (attributes, normals,
  weights, fixed indices) kept aligned; a welded or connected document is not dropped from.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from service.core.geometry import Geometry
from service.io.document import GeometryDocument

__all__ = ["FLAG_ATTRIBUTE", "LAS_OUTLIER_CLASS", "dropped_rows", "flag_holder", "with_outliers"]

#: ASPRS LAS class 7: low point (noise).
LAS_OUTLIER_CLASS = 7
#: The PLY/PCD vertex attribute that flags outliers.
FLAG_ATTRIBUTE = "outlier"
_ATTRIBUTE_FORMATS = ("ply", "pcd")
_LAS_FORMATS = ("las", "laz")


def flag_holder(fmt: str) -> str | None:
    """What holds an outlier flag in ``fmt`` (for messages), or ``None``."""
    if fmt in _LAS_FORMATS:
        return f"LAS classification {LAS_OUTLIER_CLASS}"
    if fmt in _ATTRIBUTE_FORMATS:
        return f"{fmt.upper()} vertex attribute '{FLAG_ATTRIBUTE}'"
    return None


def with_outliers(
    doc: GeometryDocument, points: NDArray[np.float64], result: Any, fmt: str
) -> tuple[GeometryDocument, NDArray[np.float64]]:
    """The document and points to write for ``result`` (its ``outliers``, ``outlier_mode``)."""
    idx = np.asarray(getattr(result, "outliers", ()), dtype=np.int64)
    mode = getattr(result, "outlier_mode", None)
    if idx.size == 0 or mode not in ("flag", "drop") or doc.weld is not None:
        return doc, points
    if dropped_rows(doc, result):
        return _dropped(doc, points, idx)
    return _flagged(doc, idx, fmt), points


def dropped_rows(doc: GeometryDocument, result: Any) -> int:
    """Rows :func:`with_outliers` leaves out of the written document (``drop``: a point cloud's
    outliers, never from a welded document)."""
    idx = np.asarray(getattr(result, "outliers", ()), dtype=np.int64)
    drops = getattr(result, "outlier_mode", None) == "drop" and doc.geometry.kind == "cloud"
    return int(idx.size) if drops and doc.weld is None else 0


def _flagged(doc: GeometryDocument, idx: NDArray[np.int64], fmt: str) -> GeometryDocument:
    attrs = dict(doc.attributes)
    n = doc.n_output
    if fmt in _LAS_FORMATS:
        old = attrs.get("classification")
        cls = np.zeros(n, np.uint8) if old is None else np.array(old, copy=True)
        cls[idx] = LAS_OUTLIER_CLASS
        attrs["classification"] = cls
        return doc.with_extras(attributes=attrs)
    if fmt in _ATTRIBUTE_FORMATS:
        flag = np.zeros(n, np.uint8)
        flag[idx] = 1
        attrs[FLAG_ATTRIBUTE] = flag
        # a PCD written back from its own records has no room for a new field: a fresh header
        layout = None if fmt == "pcd" else doc.layout
        return doc.with_extras(attributes=attrs, layout=layout)
    return doc


def _dropped(
    doc: GeometryDocument, points: NDArray[np.float64], idx: NDArray[np.int64]
) -> tuple[GeometryDocument, NDArray[np.float64]]:
    g = doc.geometry
    keep = np.ones(g.n, dtype=bool)
    keep[idx] = False
    new_index = np.cumsum(keep) - 1
    fixed = None
    if g.fixed is not None:
        fixed = new_index[g.fixed[keep[g.fixed]]]
    weights = None if g.weights is None else g.weights[keep]
    geometry = Geometry(g.points[keep], weights=weights, fixed=fixed)
    attrs = {k: v[keep] for k, v in doc.attributes.items()}
    normals = None if doc.normals is None else doc.normals[keep]
    layout = doc.layout if doc.source_format == "xyz" else None  # record layouts hold n rows
    out = doc.with_extras(geometry=geometry, attributes=attrs, normals=normals, layout=layout)
    return out, points[keep]
