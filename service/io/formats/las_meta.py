"""LAS/LAZ header facts and records (issue 41): the file's CRS, a summary like
``pdal info --summary``, the header of a reprojected output, and what smoothed a file.

* :func:`file_crs`: the CRS of the WKT or GeoTIFF-key VLRs (``laspy.LasHeader.parse_crs``), or
  ``None``;
* :func:`summary`: version, point format, dimensions with their types, point count, scales,
  offsets, bounds in the file's units, the CRS (EPSG, name, unit), class counts and the
  header's generating software, system identifier and creation date;
* :func:`reprojected_header`: the input's header for coordinates in another CRS (its CRS VLRs
  replaced, offsets moved to the new extent, scales kept);
* :func:`stamp`: an output's header records what smoothed it, as PDAL's writers.las does:
  ``generating_software`` ``"geosmooth <version>"``, ``system_identifier``
  ``"geosmooth smoothing"`` and today's creation date.

Kept apart from :mod:`.las` (its reader and writer, and the hostile-file checks).
"""

from __future__ import annotations

import contextlib
import datetime
import struct
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "assign_crs",
    "crs_facts",
    "file_crs",
    "reprojected_header",
    "stamp",
    "summary",
]

_CRS_VLRS = ("WktCoordinateSystemVlr", "GeoKeyDirectoryVlr", "GeoDoubleParamsVlr",
             "GeoAsciiParamsVlr")  # fmt: skip


def file_crs(header: Any) -> Any:
    """The ``pyproj.CRS`` a LAS header declares (WKT first, then GeoTIFF keys), or ``None``."""
    with contextlib.suppress(Exception):  # pyproj cannot parse every GeoTIFF-key set
        return header.parse_crs()
    return None


def crs_facts(crs: Any) -> dict[str, Any] | None:
    """``{"epsg", "name", "unit", "projected"}`` of a ``pyproj.CRS`` (``None``: no CRS)."""
    if crs is None:
        return None
    axes = crs.axis_info
    return {
        "epsg": crs.to_epsg(),
        "name": str(crs.name),
        "unit": axes[0].unit_name if axes else None,
        "projected": bool(crs.is_projected),
    }


def summary(header: Any, points: NDArray[np.float64], attrs: Mapping[str, Any]) -> dict[str, Any]:
    """What ``geosmooth info`` shows of a LAS/LAZ file (see the module docstring)."""
    fmt = header.point_format
    dims = [{"name": d.name, "type": f"{d.num_bits} bits" if d.dtype is None else str(d.dtype)}
            for d in fmt.dimensions]  # fmt: skip
    out: dict[str, Any] = {
        "las_version": str(header.version),
        "point_format": int(fmt.id),
        "point_count": len(points),
        "dimensions": dims,
        "scales": [float(s) for s in header.scales],
        "offsets": [float(o) for o in header.offsets],
        "bounds": {"min": points.min(axis=0).tolist(), "max": points.max(axis=0).tolist()},
        "crs": crs_facts(file_crs(header)),
        "generating_software": str(header.generating_software).strip("\0 "),
        "system_identifier": str(header.system_identifier).strip("\0 "),
        "creation_date": None if header.creation_date is None else str(header.creation_date),
    }
    classes = attrs.get("classification")
    if classes is not None:
        codes, counts = np.unique(np.asarray(classes), return_counts=True)
        out["classes"] = {str(int(c)): int(k) for c, k in zip(codes, counts, strict=True)}
    return out


def assign_crs(header: Any, crs: Any) -> None:
    """Give ``header`` the CRS ``crs`` (PDAL's ``a_srs``): its CRS VLRs replaced."""
    header.vlrs = [v for v in header.vlrs if type(v).__name__ not in _CRS_VLRS]
    header.add_crs(crs)


def reprojected_header(header: Any, crs: Any, points: NDArray[np.float64]) -> Any:
    """A copy of ``header`` for ``points`` in ``crs``: the CRS VLRs replaced (WKT for point
    formats 6-10, else GeoTIFF keys: ``laspy.LasHeader.add_crs``), the x and y offsets a round
    value below the new minimum so the 32-bit integers hold the new extent; scales and the z
    offset kept."""
    import copy

    new = copy.deepcopy(header)
    assign_crs(new, crs)
    scales = np.asarray(new.scales, dtype=np.float64)
    offsets = np.array(new.offsets, dtype=np.float64)
    offsets[:2] = np.floor(points[:, :2].min(axis=0) / scales[:2] / 1000.0) * 1000.0 * scales[:2]
    new.offsets = offsets  # z is as read: its offset (and its integers) kept
    return new


def stamp(head: bytearray | memoryview, version: str, today: datetime.date | None = None) -> None:
    """Record in a written LAS/LAZ file's first 94 bytes what smoothed it, as PDAL's writers.las
    does: ``system_identifier`` ``"geosmooth smoothing"``, ``generating_software``
    ``"geosmooth <version>"`` and the creation day of year and year (fixed offsets of every LAS
    version's public header block, uncompressed in LAZ too)."""
    day = today or datetime.date.today()
    head[26:58] = _field("geosmooth smoothing")
    head[58:90] = _field(f"geosmooth {version}")
    head[90:94] = struct.pack("<HH", day.timetuple().tm_yday, day.year)


def _field(text: str) -> bytes:
    return text.encode("ascii", "replace")[:32].ljust(32, b"\0")
