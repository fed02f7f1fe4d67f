"""File formats <-> :class:`~service.core.geometry.Geometry`, keeping everything else of the file.

Public API (see ``docs/CONTRACTS.md`` and ``service/io/README.md``)::

    doc = read_geometry("bunny.ply")                  # -> GeometryDocument
    doc.geometry                                      # validated Geometry for the engine
    data = write_geometry(doc, "ply", smoothed_points, normals="recompute", precision="input")
    save_geometry(doc, "out.laz", points=smoothed)    # streamed to a file

Every format is an entry of :data:`FORMATS` (:mod:`.registry`) with its own module, whose
docstring states exactly what is read and written. Writers receive the plain document of
:mod:`.plain` (un-welded once, normals recomputed once).
"""

from service.io.dispatch import (
    detect_format,
    read_geometry,
    save_geometry,
    sniff_format,
    write_geometry,
)
from service.io.document import GeometryDocument, Polyline, Precision, WeldMap
from service.io.errors import FormatError, UnsupportedFormat
from service.io.formats.json.codec import document_to_json_obj, geometry_from_json_obj
from service.io.formats.json.schema import GEOMETRY_JSON_SCHEMA
from service.io.limits import InputTooLarge, ReadLimits
from service.io.registry import FORMATS, Format, get_format

__all__ = [
    "FORMATS",
    "GEOMETRY_JSON_SCHEMA",
    "Format",
    "FormatError",
    "GeometryDocument",
    "InputTooLarge",
    "Polyline",
    "Precision",
    "ReadLimits",
    "UnsupportedFormat",
    "WeldMap",
    "detect_format",
    "document_to_json_obj",
    "geometry_from_json_obj",
    "get_format",
    "read_geometry",
    "save_geometry",
    "sniff_format",
    "write_geometry",
]
