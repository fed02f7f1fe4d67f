"""File formats: PLY, OBJ, XYZ and geosmooth JSON  <->  :class:`~service.core.geometry.Geometry`.

Public API (see ``docs/CONTRACTS.md``)::

    doc = read_geometry("bunny.ply", weld=False)     # -> GeometryDocument
    doc.geometry                                      # validated Geometry for the engine
    data = write_geometry(doc, "obj", smoothed_points)  # -> bytes

Each format lives in its own module (:mod:`.ply`, :mod:`.obj`, :mod:`.xyz`, :mod:`.jsonfmt`),
whose docstring states exactly what is read and written. Welding is in :mod:`.weld`.
"""

from service.io.document import GeometryDocument, Polyline, WeldMap
from service.io.errors import FormatError, UnsupportedFormat
from service.io.formats import detect_format, read_geometry, sniff_format, write_geometry
from service.io.jsonfmt import GEOMETRY_JSON_SCHEMA, document_to_json_obj, geometry_from_json_obj
from service.io.registry import FORMATS, Format, get_format

__all__ = [
    "FORMATS",
    "GEOMETRY_JSON_SCHEMA",
    "Format",
    "FormatError",
    "GeometryDocument",
    "Polyline",
    "UnsupportedFormat",
    "WeldMap",
    "detect_format",
    "document_to_json_obj",
    "geometry_from_json_obj",
    "get_format",
    "read_geometry",
    "sniff_format",
    "write_geometry",
]
