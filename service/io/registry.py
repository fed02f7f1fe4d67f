"""The format registry: one table ``{name: Format}`` that every layer reads.

The API's media types and enums, the CLI's ``--format`` choices, the jobs' format check, the
extension and content detection all come from :data:`FORMATS`; a new format is one entry here
plus its reader/writer module and its content test (:mod:`service.io.formats.magic`). Readers
take a :class:`~service.io.source.Source` and return a
:class:`~service.io.document.GeometryDocument`; writers take the plain (un-welded) document of
:mod:`service.io._shared.plain` and a binary stream. Modules are imported on first use, so the CLI
does not pay for laspy, trimesh or ezdxf when it reads a PLY.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, BinaryIO

from service.io.errors import UnsupportedFormat
from service.io.formats.magic import SNIFFERS, Sniffer

__all__ = [
    "ALL_KINDS",
    "FORMATS",
    "Format",
    "format_for_name",
    "get_format",
    "sniff",
    "supported_text",
]

#: The kinds of input a format can hold (see :attr:`Format.kinds`).
ALL_KINDS = frozenset({"mesh", "polyline", "cloud"})
_CLOUD = frozenset({"cloud"})
_COLOURS = ("red", "green", "blue", "alpha")

Reader = Callable[..., Any]
Writer = Callable[..., None]


def _lazy(module: str, name: str) -> Callable[..., Any]:
    """``service.io.<module>.<name>``, imported when first called."""

    def call(*args: Any, **kwargs: Any) -> Any:
        fn = getattr(importlib.import_module(f"service.io.{module}"), name)
        return fn(*args, **kwargs)

    call.__name__ = name
    call.__qualname__ = name
    return call


@dataclass(frozen=True)
class Format:
    """One file format.

    Attributes
    ----------
    name : str
        Registry key, e.g. ``"ply"``.
    read : callable
        ``read(source: Source, *, weld: bool, **options) -> GeometryDocument``.
    write : callable or None
        ``write(plain: PlainDocument, out: BinaryIO) -> None``; ``None`` for read-only formats.
    media_type : str
        HTTP ``Content-Type`` of a file of this format.
    extensions : tuple of str
        File name extensions (lower case, without the dot); the first is the canonical one.
    title : str
        Human name for messages and documentation.
    options : tuple of str
        Reader keyword options the format understands (e.g. ``xyz_dims``).
    weld_default : bool
        Whether reading welds coincident vertices unless told otherwise (triangle soups).
    sniff : callable or None
        ``sniff(head, size) -> bool``: whether the first bytes look like this format.
    binary : bool
        Whether files are binary (``False``: text).
    kinds : frozenset of str
        What a file of this format can hold: ``"mesh"`` (faces), ``"polyline"`` (edges,
        polylines), ``"cloud"`` (points only). A document needing a kind not listed is refused
        before smoothing (:func:`service.io.dispatch.check_output`).
    geographic_only : bool
        Coordinates are longitude/latitude (WGS84): only documents read from a geographic
        format can be written.
    min_dims, max_dims : int, int or None
        Fewest and most coordinates per point (``None``: any number).
    attributes : "all" or tuple of str
        Per-vertex attributes a file of this format written from *another* format keeps
        (``"all"``: every numeric one; a file written back in its own format keeps everything).
    coordinates : {"float64", "float32", "float32-offset"}
        Widest coordinate type: ``float32`` formats are refused for georeferenced double input
        (precision they cannot keep); ``float32-offset`` stores float32 about a double offset.
    """

    name: str
    read: Reader
    write: Writer | None
    media_type: str
    extensions: tuple[str, ...]
    title: str
    options: tuple[str, ...] = field(default_factory=tuple)
    weld_default: bool = False
    sniff: Sniffer | None = None
    binary: bool = False
    kinds: frozenset[str] = ALL_KINDS
    geographic_only: bool = False
    min_dims: int = 2
    max_dims: int | None = 3
    attributes: str | tuple[str, ...] = "all"
    coordinates: str = "float64"

    @property
    def extension(self) -> str:
        """The canonical extension (``"ply"``)."""
        return self.extensions[0]

    def keeps(self, attribute: str) -> bool:
        """Whether a file written from another format keeps this per-vertex attribute."""
        return self.attributes == "all" or attribute in self.attributes

    def write_to(self, plain: Any, out: BinaryIO) -> None:
        """Write ``plain`` to ``out``; :class:`UnsupportedFormat` for read-only formats."""
        if self.write is None:
            raise UnsupportedFormat(f"{self.title} can be read but not written", fmt=self.name)
        self.write(plain, out)


def _f(name: str, module: str, media: str, exts: tuple[str, ...], title: str, **kw: Any) -> Format:
    writer = kw.pop("writer", (module, f"write_{name}"))
    kw.setdefault("sniff", SNIFFERS[name])
    return Format(
        name,
        _lazy(module, f"read_{name}"),
        _lazy(*writer) if writer else None,
        media,
        exts,
        title,
        **kw,
    )


_OCTET = "application/octet-stream"
_TABLE: dict[str, Format] = {
    f.name: f
    for f in (
        _f(
            "ply",
            "formats.ply.read",
            _OCTET,
            ("ply",),
            "PLY",
            writer=("formats.ply.write", "write_ply"),
            binary=True,
        ),
        _f(
            "obj",
            "formats.obj.read",
            "model/obj",
            ("obj",),
            "OBJ",
            writer=("formats.obj.write", "write_obj"),
            attributes=(*_COLOURS[:3], "uv"),
        ),
        _f(
            "xyz",
            "formats.xyz",
            "text/plain; charset=utf-8",
            ("xyz", "txt", "csv", "pts"),
            "XYZ",
            options=("xyz_dims",),
            kinds=_CLOUD,
            max_dims=None,
        ),
        _f(
            "json",
            "formats.json.codec",
            "application/json",
            ("json",),
            "geosmooth JSON",
            min_dims=1,
            max_dims=None,
        ),
        _f(
            "stl",
            "formats.stl",
            "model/stl",
            ("stl",),
            "STL",
            weld_default=True,
            binary=True,
            kinds=frozenset({"mesh"}),
            attributes=(),
            coordinates="float32",
        ),
        _f(
            "off",
            "formats.off",
            "text/plain; charset=utf-8",
            ("off",),
            "OFF",
            kinds=frozenset({"mesh", "cloud"}),
            attributes=(),
        ),
        _f(
            "glb",
            "formats.glb",
            "model/gltf-binary",
            ("glb",),
            "glTF binary",
            weld_default=True,
            binary=True,
            kinds=frozenset({"mesh", "cloud"}),
            attributes=(*_COLOURS, "color"),
            coordinates="float32-offset",
        ),
        _f(
            "las",
            "formats.las",
            "application/vnd.las",
            ("las",),
            "LAS",
            binary=True,
            kinds=_CLOUD,
        ),
        _f(
            "laz",
            "formats.las",
            "application/vnd.laszip",
            ("laz",),
            "LAZ",
            binary=True,
            kinds=_CLOUD,
        ),
        _f(
            "pcd",
            "formats.pcd",
            _OCTET,
            ("pcd",),
            "PCD",
            binary=True,
            kinds=_CLOUD,
        ),
        _f(
            "e57",
            "formats.e57",
            "model/e57",
            ("e57",),
            "E57",
            binary=True,
            kinds=_CLOUD,
            attributes=("intensity", *_COLOURS[:3]),
        ),
        _f(
            "gpx",
            "formats.gpx",
            "application/gpx+xml",
            ("gpx",),
            "GPX",
            options=("geographic",),
            kinds=frozenset({"polyline"}),
            geographic_only=True,
            attributes=(),
        ),
        _f(
            "geojson",
            "formats.geojson",
            "application/geo+json",
            ("geojson",),
            "GeoJSON",
            options=("geographic",),
            kinds=frozenset({"polyline"}),
            geographic_only=True,
            attributes=(),
        ),
        _f(
            "dxf",
            "formats.dxf",
            "image/vnd.dxf",
            ("dxf",),
            "DXF",
            attributes=(),
        ),
    )
}

#: name -> Format, in the order shown to users. Iterating gives the names.
FORMATS: Mapping[str, Format] = MappingProxyType(_TABLE)

# content detection order: magic numbers first, then the text formats from the most specific
_SNIFF_ORDER = (
    "glb", "las", "laz", "e57", "ply", "stl", "pcd", "off", "gpx", "dxf", "geojson", "json",
    "obj", "xyz",
)  # fmt: skip


def supported_text() -> str:
    """One sentence listing the formats (for error messages)."""
    names = ", ".join(f"{f.title} (.{f.extension})" for f in FORMATS.values())
    return f"geosmooth reads and writes {names}"


def get_format(name: str) -> Format:
    """The format called ``name`` (case-insensitive, a leading dot allowed).

    Raises
    ------
    UnsupportedFormat
        For names not in the registry.
    """
    key = str(name).lower().lstrip(".")
    fmt = FORMATS.get(key) or format_for_name(f"x.{key}")
    if fmt is None:
        raise UnsupportedFormat(f"format {name!r} is not supported: {supported_text()}", fmt=key)
    return fmt


def format_for_name(filename: str) -> Format | None:
    """The format a file name's extension names, or ``None`` when no format claims it."""
    suffix = Path(str(filename)).suffix.lower().lstrip(".")
    return next((f for f in FORMATS.values() if suffix in f.extensions), None)


def sniff(head: bytes, size: int) -> str | None:
    """The format the first bytes of a file (and its size) show, or ``None``."""
    for name in _SNIFF_ORDER:
        test = FORMATS[name].sniff
        if test is not None and test(head, size):
            return name
    return None
