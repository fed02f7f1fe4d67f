"""What the first bytes of a file look like in each format: the content tests of format
detection (magic numbers, then text signatures), keyed by the format's registry name.

:data:`SNIFFERS` maps a name of :data:`service.io.registry.FORMATS` to ``test(head, size) ->
bool`` (``head``: the file's first bytes, ``size``: its length in bytes); the registry gives each
format its test and tries them in its detection order (:func:`service.io.registry.sniff`).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from types import MappingProxyType

__all__ = ["SNIFFERS", "Sniffer"]

Sniffer = Callable[[bytes, int], bool]


def _text_start(head: bytes) -> bytes:
    return head.lstrip(b"\xef\xbb\xbf \t\r\n")


_PCD = re.compile(rb"\A(?:[ \t]*#[^\n]*\n|\s*\n)*\s*(?:VERSION|FIELDS)\b")
_OFF = re.compile(rb"\A(?:\s*#[^\n]*\n)*\s*(?:ST)?C?N?4?n?OFF\b")
_DXF = re.compile(rb"\A\s*(?:999\s*\n[^\n]*\n\s*)*0\s*\n\s*SECTION\b")
_GEOJSON = re.compile(
    rb'"type"\s*:\s*"(?:FeatureCollection|Feature|LineString|MultiLineString|Polygon|'
    rb'MultiPolygon|Point|MultiPoint|GeometryCollection)"'
)
_OBJ_KEYS = {b"v", b"vn", b"vt", b"f", b"l", b"o", b"g", b"mtllib", b"usemtl", b"s", b"vp"}


def _stl_binary(head: bytes, size: int) -> bool:
    if len(head) < 84:
        return False
    count = int.from_bytes(head[80:84], "little")
    return 84 + 50 * count == size


def _stl_ascii(head: bytes, size: int) -> bool:
    text = _text_start(head)
    return text[:5].lower() == b"solid" and b"facet" in text and not _stl_binary(head, size)


def _laz(head: bytes, size: int) -> bool:
    return head[:4] == b"LASF" and len(head) > 104 and bool(head[104] & 0xC0)


def _las(head: bytes, size: int) -> bool:
    return head[:4] == b"LASF" and not _laz(head, size)


def _json(head: bytes, size: int) -> bool:
    return _text_start(head)[:1] in (b"{", b"[") and not _GEOJSON.search(head)


def _geojson(head: bytes, size: int) -> bool:
    return _text_start(head)[:1] == b"{" and bool(_GEOJSON.search(head))


def _gpx(head: bytes, size: int) -> bool:
    return _text_start(head)[:1] == b"<" and b"<gpx" in head


def _obj(head: bytes, size: int) -> bool:
    for line in head.split(b"\n")[:-1] or head.split(b"\n"):
        words = line.split()
        if not words or words[0].startswith(b"#"):
            continue
        return words[0] in _OBJ_KEYS
    return False


def _xyz(head: bytes, size: int) -> bool:
    for line in head.split(b"\n")[:-1] or head.split(b"\n"):
        words = line.replace(b",", b" ").split()
        if not words or words[0].startswith(b"#"):
            continue
        try:
            [float(w) for w in words]
        except ValueError:
            continue
        return True
    return False


def _ply(head: bytes, size: int) -> bool:
    return head.startswith((b"ply\n", b"ply\r\n"))


def _stl(head: bytes, size: int) -> bool:
    return _stl_binary(head, size) or _stl_ascii(head, size)


def _off(head: bytes, size: int) -> bool:
    return bool(_OFF.match(head))


def _glb(head: bytes, size: int) -> bool:
    return head[:4] == b"glTF"


def _pcd(head: bytes, size: int) -> bool:
    return bool(_PCD.match(head))


def _e57(head: bytes, size: int) -> bool:
    return head[:8] == b"ASTM-E57"


def _dxf(head: bytes, size: int) -> bool:
    return bool(_DXF.match(head)) or head.startswith(b"AutoCAD Binary DXF")


#: Format name -> its content test.
SNIFFERS: Mapping[str, Sniffer] = MappingProxyType(
    {
        "ply": _ply,
        "obj": _obj,
        "xyz": _xyz,
        "json": _json,
        "stl": _stl,
        "off": _off,
        "glb": _glb,
        "las": _las,
        "laz": _laz,
        "pcd": _pcd,
        "e57": _e57,
        "gpx": _gpx,
        "geojson": _geojson,
        "dxf": _dxf,
    }
)
