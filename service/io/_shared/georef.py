"""Georeference of geographic input (GPX, GeoJSON) written to a projected format.

Longitude/latitude are smoothed in metres in the local east/north/up frame about the data's
centre (:mod:`.geo`). Written to a format that holds no longitude/latitude (PLY, OBJ, DXF, LAS,
...), the result is either

* **the local frame** (default): metres east/north/up of the origin ``(lon0, lat0)`` on the
  WGS84 ellipsoid (height 0), i.e. the PROJ pipeline
  ``+proj=pipeline +step +proj=unitconvert +xy_in=deg +xy_out=rad +step +proj=cart
  +ellps=WGS84 +step +proj=topocentric +ellps=WGS84 +lon_0=.. +lat_0=.. +h_0=0`` applied to
  (longitude, latitude, ellipsoidal height); or
* **a projected CRS** (writer option ``crs``: an EPSG code such as ``32633`` / ``"EPSG:32633"``,
  or ``"utm"`` for the UTM zone of the data's centre): easting, northing (pyproj, from WGS84
  longitude/latitude) and the elevation as read (0 without elevations).

The frame is recorded where the format holds one (:class:`Georef`): LAS/LAZ a WKT VLR (LAS 1.4,
point format 6/7; the local frame as an engineering CRS whose remark holds the pipeline), DXF the
``$LATITUDE``/``$LONGITUDE`` header variables of the origin plus custom properties
``CRS`` and ``CRS_FRAME``, PLY/OBJ header comments (and geosmooth JSON's ``comments``). XYZ, OFF,
PCD, E57 and glTF record nothing (no comment or CRS field geosmooth writes there yet). Which of
the two an output gets is decided by :func:`service.io.holds.georeference`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from service.io._shared.geo import LocalFrame

__all__ = ["CrsOption", "Georef", "epsg_of", "project", "reproject", "target_crs", "utm_epsg"]

CrsOption = str | int | None


@dataclass(frozen=True)
class Georef:
    """The frame of written coordinates.

    Attributes
    ----------
    crs : str
        ``"EPSG:<code>"`` of a projected CRS, or ``"local"`` (east/north/up about the origin).
    origin : tuple of float
        Longitude, latitude (degrees) and ellipsoidal height (m) of the local frame's origin.
    name : str
        The CRS's name (``"WGS 84 / UTM zone 33N"``) or a description of the local frame.
    """

    crs: str
    origin: tuple[float, float, float]
    name: str

    @property
    def pipeline(self) -> str:
        """PROJ pipeline from (lon, lat, h) in degrees/metres to local east/north/up."""
        lon0, lat0, h0 = self.origin
        return (
            "+proj=pipeline +step +proj=unitconvert +xy_in=deg +xy_out=rad +step +proj=cart"
            f" +ellps=WGS84 +step +proj=topocentric +ellps=WGS84 +lon_0={lon0!r}"
            f" +lat_0={lat0!r} +h_0={h0!r}"
        )

    def lines(self) -> list[str]:
        """Header comment lines stating the frame (PLY, OBJ, JSON)."""
        lon0, lat0, _ = self.origin
        if self.crs != "local":
            return [f"crs {self.crs} ({self.name}); smoothed about lon {lon0!r} lat {lat0!r}"]
        return [
            f"crs local east/north/up metres about lon {lon0!r} lat {lat0!r} (WGS 84 ellipsoid,"
            " height 0)",
            f"crs_pipeline {self.pipeline}",
        ]

    def wkt(self) -> str:
        """WKT of the CRS (an engineering CRS for the local frame; needs pyproj for EPSG)."""
        if self.crs != "local":
            import pyproj

            return str(pyproj.CRS.from_user_input(self.crs).to_wkt())
        metre = 'LENGTHUNIT["metre",1]'
        axes = ",".join(
            f'AXIS["{a}",{d},ORDER[{i}],{metre}]'
            for i, (a, d) in enumerate((("E", "east"), ("N", "north"), ("U", "up")), start=1)
        )
        return (
            f'ENGCRS["{self.name}",EDATUM["topocentric origin lon {self.origin[0]!r} lat '
            f'{self.origin[1]!r} h 0 on WGS 84"],CS[Cartesian,3],{axes},'
            f'REMARK["{self.pipeline}"]]'
        )


def utm_epsg(lon: float, lat: float) -> int:
    """EPSG code of the WGS84 UTM zone holding ``(lon, lat)`` (326zz north, 327zz south)."""
    zone = int(np.floor((lon + 180.0) / 6.0)) % 60 + 1
    return (32600 if lat >= 0 else 32700) + zone


def target_crs(option: CrsOption, frame: LocalFrame) -> str:
    """``"EPSG:<code>"`` of the ``crs`` option (``ValueError`` for anything else)."""
    return epsg_of(option, frame.lon0, frame.lat0)


def epsg_of(option: CrsOption, lon0: float, lat0: float) -> str:
    """``"EPSG:<code>"`` of the ``crs`` option, ``"utm"`` being the zone of ``(lon0, lat0)``."""
    text = str(option).strip()
    if text.lower() == "utm":
        return f"EPSG:{utm_epsg(lon0, lat0)}"
    code = text.upper().removeprefix("EPSG:")
    if not code.isdigit():
        raise ValueError(
            f"crs must be an EPSG code (e.g. 32633 or 'EPSG:32633') or 'utm', got {option!r}"
        )
    return f"EPSG:{int(code)}"


def project(target: str, lon: Any, lat: Any, ele: Any) -> tuple[Any, str]:
    import pyproj

    try:
        crs = pyproj.CRS.from_user_input(target)
    except pyproj.exceptions.CRSError:
        raise ValueError(f"crs {target} is not a CRS pyproj knows") from None
    if not crs.is_projected:
        raise ValueError(f"crs {target} ({crs.name}) is not a projected CRS")
    to = pyproj.Transformer.from_crs("EPSG:4326", crs, always_xy=True)
    x, y = to.transform(lon, lat)
    z = np.zeros_like(lon) if ele is None else ele
    pts = np.column_stack([x, y, z])
    if not np.isfinite(pts).all():
        raise ValueError(f"crs {target} ({crs.name}) cannot hold these points (outside its area)")
    return pts, str(crs.name)


def reproject(source: Any, option: CrsOption, points: Any) -> tuple[Any, Georef]:
    """Points of a projected (or geographic) CRS ``source`` (a ``pyproj.CRS``, e.g. a LAS file's)
    in the projected CRS of the ``crs`` option, like PDAL's ``filters.reprojection`` with the
    file's ``a_srs`` and ``out_srs``: x, y transformed (pyproj, ``always_xy``), z as read.
    ``"utm"`` is the WGS84 UTM zone of the points' centre. Returns the points and the
    :class:`Georef` naming the resolved EPSG (``ValueError`` for a CRS that cannot hold them)."""
    import pyproj

    pts = np.asarray(points, dtype=np.float64)
    centre = (pts.min(axis=0) + pts.max(axis=0)) / 2
    to_wgs = pyproj.Transformer.from_crs(source, "EPSG:4326", always_xy=True)
    lon0, lat0 = (float(v) for v in to_wgs.transform(centre[0], centre[1]))
    target = epsg_of(option, lon0, lat0)
    crs = pyproj.CRS.from_user_input(target)
    if not crs.is_projected:
        raise ValueError(f"crs {target} ({crs.name}) is not a projected CRS")
    x, y = pyproj.Transformer.from_crs(source, crs, always_xy=True).transform(pts[:, 0], pts[:, 1])
    out = np.column_stack([x, y, pts[:, 2:]])
    if not np.isfinite(out).all():
        raise ValueError(f"crs {target} ({crs.name}) cannot hold these points (outside its area)")
    return out, Georef(target, (lon0, lat0, 0.0), str(crs.name))
