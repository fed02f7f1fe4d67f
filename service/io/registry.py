"""The format registry: one table ``{name: Format}`` that every layer reads.

The API's media types and enums, the CLI's ``--format`` choices and the jobs' format check all
come from :data:`FORMATS`; a new format is one entry here plus its reader/writer module.
Readers take the file's bytes and return a :class:`~service.io.document.GeometryDocument`;
writers take a plain (un-welded) document and return bytes.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

from service.io.document import GeometryDocument
from service.io.errors import UnsupportedFormat
from service.io.jsonfmt import read_json, write_json
from service.io.obj import read_obj, write_obj
from service.io.ply import read_ply, write_ply
from service.io.xyz import read_xyz, write_xyz

__all__ = ["FORMATS", "Format", "format_for_name", "get_format"]

Reader = Callable[..., GeometryDocument]
Writer = Callable[..., bytes]


@dataclass(frozen=True)
class Format:
    """One file format.

    Attributes
    ----------
    name : str
        Registry key, e.g. ``"ply"``.
    read : callable
        ``read(data: bytes, *, weld: bool, **options) -> GeometryDocument``.
    write : callable or None
        ``write(doc, points, **options) -> bytes``; ``None`` for read-only formats.
    media_type : str
        HTTP ``Content-Type`` of a file of this format.
    extensions : tuple of str
        File name extensions (lower case, without the dot); the first is the canonical one.
    title : str
        Human name for messages and documentation.
    options : tuple of str
        Reader/writer keyword options the format understands (e.g. ``xyz_dims``).
    """

    name: str
    read: Reader
    write: Writer | None
    media_type: str
    extensions: tuple[str, ...]
    title: str
    options: tuple[str, ...] = field(default_factory=tuple)

    @property
    def extension(self) -> str:
        """The canonical extension (``"ply"``)."""
        return self.extensions[0]


def _ply_write(doc: GeometryDocument, points: Any, *, ascii: bool = False, **_: Any) -> bytes:
    return write_ply(doc, points, ascii=ascii)


def _plain_write(writer: Callable[[GeometryDocument, Any], bytes]) -> Writer:
    def write(doc: GeometryDocument, points: Any, **_: Any) -> bytes:
        return writer(doc, points)

    return write


_TABLE: dict[str, Format] = {
    f.name: f
    for f in (
        Format("ply", read_ply, _ply_write, "application/octet-stream", ("ply",), "PLY"),
        Format("obj", read_obj, _plain_write(write_obj), "model/obj", ("obj",), "OBJ"),
        Format(
            "xyz",
            read_xyz,
            _plain_write(write_xyz),
            "text/plain; charset=utf-8",
            ("xyz",),
            "XYZ",
            ("xyz_dims",),
        ),
        Format("json", read_json, _plain_write(write_json), "application/json", ("json",), "JSON"),
    )
}

#: name -> Format, in the order shown to users. Iterating gives the names.
FORMATS: Mapping[str, Format] = MappingProxyType(_TABLE)


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
    fmt = FORMATS.get(key)
    if fmt is None:
        raise UnsupportedFormat(f"format {name!r} is not supported: {supported_text()}", fmt=key)
    return fmt


def format_for_name(filename: str) -> Format | None:
    """The format a file name's extension names, or ``None`` when no format claims it."""
    suffix = Path(str(filename)).suffix.lower().lstrip(".")
    return next((f for f in FORMATS.values() if suffix in f.extensions), None)
