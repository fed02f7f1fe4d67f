"""PLY header: ``ply``, ``format``, ``element``/``property`` declarations, ``end_header``.

``comment`` and ``obj_info`` lines are kept (and written back). Type names may be the classic
(``uchar``, ``int``, ``float``) or the sized spelling (``uint8``, ``int32``, ``float32``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from service.io.errors import FormatError

__all__ = ["PLY_TYPES", "PlyElement", "PlyHeader", "PlyProperty", "parse_header"]

PLY_TYPES: dict[str, str] = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}

ENCODINGS = ("ascii", "binary_little_endian", "binary_big_endian")

_END = re.compile(rb"(?m)^end_header[ \t\r]*(?:\n|\Z)")


@dataclass(frozen=True)
class PlyProperty:
    """One property: a scalar (``count_type is None``) or a list."""

    name: str
    type: str
    count_type: str | None = None

    @property
    def is_list(self) -> bool:
        """Whether this is a ``property list``."""
        return self.count_type is not None


@dataclass
class PlyElement:
    """An element declaration and its properties."""

    name: str
    count: int
    properties: list[PlyProperty] = field(default_factory=list)

    def find(self, *names: str) -> PlyProperty | None:
        """The first property whose name is one of ``names``."""
        for name in names:
            for prop in self.properties:
                if prop.name == name:
                    return prop
        return None


@dataclass
class PlyHeader:
    """A parsed header.

    Attributes
    ----------
    encoding : str
        ``"ascii"``, ``"binary_little_endian"`` or ``"binary_big_endian"``.
    elements : list of PlyElement
        In file order.
    body_offset : int
        Byte offset of the first byte after the header.
    n_lines : int
        Number of header lines, including ``end_header`` (for line numbers of ASCII bodies).
    comments : list of str
        Text of the ``comment`` lines.
    obj_info : list of str
        Text of the ``obj_info`` lines.
    """

    encoding: str
    elements: list[PlyElement]
    body_offset: int
    n_lines: int
    comments: list[str] = field(default_factory=list)
    obj_info: list[str] = field(default_factory=list)


def _fail(message: str, line: int | None = None) -> FormatError:
    where = f"PLY header line {line}: " if line is not None else "PLY header: "
    return FormatError(where + message, fmt="ply", line=line)


def _header_lines(data: bytes) -> tuple[list[str], int]:
    """The header's lines (without ``end_header``) and the offset of the body."""
    if not data.strip():
        raise FormatError("the file is empty", fmt="ply")
    if not data.startswith(b"ply"):
        raise _fail("the file does not start with 'ply' (not a PLY file)", 1)
    end = _END.search(data)
    if end is None:
        raise _fail("no 'end_header' line (the header is truncated or not PLY)")
    text = data[: end.start()].decode("ascii", errors="replace")
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    return lines, end.end()


def parse_header(data: bytes) -> PlyHeader:
    """Parse the header of a PLY file.

    Raises
    ------
    FormatError
        Missing ``ply`` magic, ``format`` or ``end_header``; unknown keywords or types; bad
        element counts; properties outside an element.
    """
    lines, body = _header_lines(data)
    encoding: str | None = None
    elements: list[PlyElement] = []
    comments: list[str] = []
    obj_info: list[str] = []
    for number, raw in enumerate(lines, start=1):
        words = raw.split()
        if number == 1:
            if words != ["ply"]:
                raise _fail("the first line must be 'ply'", 1)
            continue
        if words and words[0] == "comment":
            comments.append(raw.strip()[len("comment") :].strip())
            continue
        if words and words[0] == "obj_info":
            obj_info.append(raw.strip()[len("obj_info") :].strip())
            continue
        if not words:
            continue
        key = words[0]
        if key == "format":
            if len(words) != 3 or words[1] not in ENCODINGS:
                raise _fail(
                    f"bad format line {raw.strip()!r}; expected 'format ascii|binary_little_endian"
                    "|binary_big_endian 1.0'",
                    number,
                )
            encoding = words[1]
        elif key == "element":
            if len(words) != 3 or not words[2].isdigit():
                raise _fail(
                    f"bad element line {raw.strip()!r}; expected 'element NAME COUNT'", number
                )
            elements.append(PlyElement(words[1], int(words[2])))
        elif key == "property":
            if not elements:
                raise _fail("property declared before any element", number)
            elements[-1].properties.append(_property(words, raw, number))
        else:
            raise _fail(f"unknown keyword {key!r}", number)
    if encoding is None:
        raise _fail("no 'format' line")
    for el in elements:
        if el.count and not el.properties:
            raise _fail(f"element {el.name!r} has no properties")
    return PlyHeader(encoding, elements, body, len(lines) + 1, comments, obj_info)


def _property(words: list[str], raw: str, number: int) -> PlyProperty:
    if len(words) == 3 and words[1] != "list":
        if words[1] not in PLY_TYPES:
            raise _fail(f"unknown property type {words[1]!r}", number)
        return PlyProperty(words[2], PLY_TYPES[words[1]])
    if len(words) == 5 and words[1] == "list":
        for t in words[2:4]:
            if t not in PLY_TYPES:
                raise _fail(f"unknown property type {t!r}", number)
        if PLY_TYPES[words[2]][0] == "f":
            raise _fail(f"list count type must be an integer type, got {words[2]!r}", number)
        return PlyProperty(words[4], PLY_TYPES[words[3]], PLY_TYPES[words[2]])
    raise _fail(
        f"bad property line {raw.strip()!r}; expected 'property TYPE NAME' or"
        " 'property list COUNT_TYPE ITEM_TYPE NAME'",
        number,
    )
