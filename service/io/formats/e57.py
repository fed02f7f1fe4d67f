"""E57 (ASTM E2807) scans via pye57 (libE57Format; manylinux wheels for CPython 3.11).

Reading
-------
Every scan's points with the fields pye57 supports (``cartesianX/Y/Z`` or spherical
coordinates, ``intensity``, ``colorRed/Green/Blue``, ``rowIndex``, ``columnIndex``, the invalid
state), placed in world coordinates with the scan's pose and concatenated. Points flagged
invalid (or with NaN coordinates) are left out of the geometry and written back as they were.
Intensity, colours and row/column indices are attributes when every scan has them. Images and
fields pye57 cannot read are not kept (noted). A scan's ``recordCount`` is checked before pye57
allocates its buffers: against the file size (at the fewest bits a record of its prototype can
take) and the reader limits (:func:`service.io.limits.check_points`).

Writing
-------
A document read from E57 is written as the same scans (names, poses, fields) with each valid
point moved back into its scan's frame; spherical scans are written as cartesian ones. Other
documents become one scan (``intensity``, ``red green blue`` attributes as E57 fields).
Coordinates keep the input's precision (issue 41): single-precision coordinate fields stay
``E57_SINGLE`` (a float32 scan is not written at twice its size); anything else (double
fields, scaled integers, another format's float64 coordinates) is written as double-precision
floats (``E57_DOUBLE``): pye57 0.4 hard-codes ``E57_SINGLE`` for its point prototype, which
moved georeferenced points (5.6e6 m) by up to 0.25 m, so that write runs with pye57's
``libe57`` module seen through a proxy whose ``E57_SINGLE`` is ``E57_DOUBLE`` (nothing else
changes; the buffers were double already).
libE57 needs a real file, so bytes go through a temporary file.
"""

from __future__ import annotations

import contextlib
import os
import re
import tempfile
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any, BinaryIO

import numpy as np
from numpy.typing import NDArray

from service.io._shared.assemble import assemble
from service.io._shared.coords import as_xyz
from service.io._shared.plain import PlainDocument
from service.io.document import GeometryDocument, Precision
from service.io.errors import FormatError
from service.io.limits import check_points
from service.io.source import Source

__all__ = ["E57Layout", "read_e57", "write_e57"]

_XYZ = ("cartesianX", "cartesianY", "cartesianZ")
_SPHERICAL = ("sphericalRange", "sphericalAzimuth", "sphericalElevation")
_ATTRS = ("intensity", "colorRed", "colorGreen", "colorBlue", "rowIndex", "columnIndex")


@dataclass(frozen=True, eq=False)
class E57Layout:
    """Per scan: name, rotation (w, x, y, z), translation, raw fields, valid mask."""

    scans: list[
        tuple[str, NDArray[np.float64], NDArray[np.float64], dict[str, Any], NDArray[np.bool_]]
    ]


def _matrix(q: NDArray[np.float64]) -> NDArray[np.float64]:
    w, x, y, z = (q / np.linalg.norm(q)).tolist()
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])  # fmt: skip


def _name(header: Any, i: int) -> str:
    try:
        return str(header["name"].value())
    except Exception:  # the name is optional in E57
        return f"scan {i}"


def _record_bits(prototype: Any) -> int:
    """The fewest bits one record of a compressed vector with this prototype takes on disk
    (E57 bit-packs: a float 32 or 64 bits, an integer ``ceil(log2(max - min + 1))``)."""
    from pye57 import libe57

    bits = 0
    for j in range(prototype.childCount()):
        node = prototype.get(j)
        kind = node.type()
        if kind == libe57.E57_FLOAT:
            bits += 32 if libe57.FloatNode(node).precision() == libe57.E57_SINGLE else 64
        elif kind in (libe57.E57_INTEGER, libe57.E57_SCALED_INTEGER):
            typed = (libe57.IntegerNode if kind == libe57.E57_INTEGER
                     else libe57.ScaledIntegerNode)(node)  # fmt: skip
            bits += max(0, int(typed.maximum()) - int(typed.minimum())).bit_length()
        elif kind == libe57.E57_STRING:
            bits += 8  # a string's length prefix
    return bits


def _check_scan(header: Any, i: int, size: int) -> None:
    """Refuse a scan whose ``recordCount`` its file cannot hold, or the limits do not allow,
    before pye57 allocates a buffer of that many records per field."""
    from pye57 import libe57

    n = int(header.point_count)
    prototype = libe57.StructureNode(header.points.prototype())
    bits = _record_bits(prototype)
    if n * bits > 8 * size:
        raise FormatError(
            f"E57 scan {i} declares {n} points (recordCount), more than the file's {size}"
            f" bytes can hold at {bits} bits a point",
            fmt="e57",
        )
    # pye57's buffers (8 bytes a field at most), then xyz, its float64 copy, the valid mask,
    # the world coordinates and their concatenation
    check_points(n, 8 * prototype.childCount() + 6 * 24 + 1, "e57")


def _read_raw(e57: Any, header: Any, i: int) -> dict[str, Any]:
    """pye57's ``read_scan_raw`` (the fields it supports), with the records the reader
    delivered counted: pye57 returns its ``np.empty`` buffers whole, so a ``recordCount``
    larger than the data gave points of uninitialised memory."""
    from pye57 import libe57
    from pye57.e57 import SUPPORTED_POINT_FIELDS

    n = int(header.point_count)
    raw: dict[str, Any] = {}
    buffers = libe57.VectorSourceDestBuffer()
    for field in header.point_fields:
        if field in SUPPORTED_POINT_FIELDS:
            raw[field], buffer = e57.make_buffer(field, n)
            buffers.append(buffer)
    reader = header.points.reader(buffers)
    try:
        got = int(reader.read()) if n else 0
    finally:
        reader.close()
    if got != n:
        raise FormatError(
            f"E57 scan {i} holds {got} points, its recordCount says {n}", fmt="e57"
        )
    return raw


def _scan(e57: Any, i: int, size: int) -> tuple[Any, dict[str, Any], NDArray[np.float64]]:
    from pye57.utils import convert_spherical_to_cartesian

    header = e57.get_header(i)
    _check_scan(header, i, size)
    raw = _read_raw(e57, header, i)
    if all(c in raw for c in _XYZ):
        xyz = np.column_stack([raw[c] for c in _XYZ]).astype(np.float64)
    elif "sphericalRange" in raw:
        rae = np.column_stack(
            [raw["sphericalRange"], raw["sphericalAzimuth"], raw["sphericalElevation"]]
        )
        xyz = convert_spherical_to_cartesian(rae)
        for c in ("sphericalRange", "sphericalAzimuth", "sphericalElevation"):
            raw.pop(c)
        if "sphericalInvalidState" in raw:
            raw["cartesianInvalidState"] = raw.pop("sphericalInvalidState")
        for j, c in enumerate(_XYZ):
            raw[c] = xyz[:, j].copy()
    else:
        raise FormatError(f"E57 scan {i} has no cartesian or spherical coordinates", fmt="e57")
    return header, raw, xyz


def _single(header: Any) -> bool:
    """Whether a scan's coordinate fields are all single-precision floats."""
    from pye57 import libe57

    try:
        proto = libe57.StructureNode(header.points.prototype())
        names = [c for c in (*_XYZ, *_SPHERICAL) if proto.isDefined(c)]
        return bool(names) and all(
            libe57.FloatNode(proto.get(c)).precision() == libe57.E57_SINGLE for c in names
        )
    except Exception:  # a scaled-integer or unusual field: not single floats
        return False


def read_e57(source: Source, *, weld: bool = False) -> GeometryDocument:
    """Read every scan of an E57 file (see the module docstring)."""
    import pye57

    scans = []
    single = True
    parts: list[NDArray[np.float64]] = []
    with source.as_path(".e57") as path:
        try:
            e57 = pye57.E57(str(path))
            count = e57.scan_count
            size = os.path.getsize(path)
            for i in range(count):
                header, raw, xyz = _scan(e57, i, size)
                single = single and _single(header)
                rot = np.asarray(header.rotation, dtype=np.float64)
                trans = np.asarray(header.translation, dtype=np.float64)
                valid: NDArray[np.bool_] = np.asarray(np.isfinite(xyz).all(axis=1))
                if "cartesianInvalidState" in raw:
                    valid &= np.asarray(raw["cartesianInvalidState"]) == 0
                world = xyz[valid] @ _matrix(rot).T + trans
                parts.append(world)
                scans.append((_name(header, i), rot, trans, raw, valid))
            e57.close()
        except FormatError:
            raise
        except Exception as exc:  # libE57 raises its own exception types on bad files
            text = re.sub(r"fileName=\S*|/\S+", "", " ".join(str(exc).split()))
            text = " ".join(text.split())[:200] or type(exc).__name__
            raise FormatError(f"E57: {text}", fmt="e57") from None
    if not parts or not sum(len(p) for p in parts):
        raise FormatError("the file holds no points", fmt="e57")
    common = [a for a in _ATTRS if all(a in raw for _, _, _, raw, _ in scans)]
    attributes = {
        a: np.concatenate([np.asarray(raw[a])[valid] for _, _, _, raw, valid in scans])
        for a in common
    }
    notes = [f"{len(scans)} E57 scans, {sum(len(p) for p in parts)} valid points"]
    doc = assemble(np.concatenate(parts), fmt="e57", notes=notes, weld=weld)
    return doc.with_extras(
        attributes=attributes,
        precision=Precision("float32" if single else "float64"),
        layout=E57Layout(scans),
    )


def _scans_of(plain: PlainDocument) -> list[tuple[str, Any, Any, dict[str, Any]]]:
    layout = plain.layout
    if isinstance(layout, E57Layout) and sum(int(v.sum()) for *_, v in layout.scans) == plain.n:
        out = []
        at = 0
        for name, rot, trans, raw, valid in layout.scans:
            k = int(valid.sum())
            data = {key: np.array(value) for key, value in raw.items()}
            local = (plain.points[at : at + k] - trans) @ _matrix(rot)
            for j, c in enumerate(_XYZ):
                data[c] = data[c].astype(np.float64)
                data[c][valid] = local[:, j]
            out.append((name, rot, trans, data))
            at += k
        return out
    pts = as_xyz(plain.points, "e57")
    data = {c: np.ascontiguousarray(pts[:, j]) for j, c in enumerate(_XYZ)}
    names = {"intensity": "intensity", "red": "colorRed", "green": "colorGreen",
             "blue": "colorBlue", "colorRed": "colorRed", "colorGreen": "colorGreen",
             "colorBlue": "colorBlue"}  # fmt: skip
    for key, field in names.items():
        if key in plain.attributes and plain.attributes[key].ndim == 1:
            data[field] = np.asarray(plain.attributes[key])
    return [("geosmooth", np.array([1.0, 0, 0, 0]), np.zeros(3), data)]


_DOUBLE_LOCK = threading.Lock()


class _DoublePrecision:
    """pye57's ``libe57`` with ``E57_SINGLE`` meaning ``E57_DOUBLE``."""

    def __init__(self, lib: Any) -> None:
        self._lib = lib

    def __getattr__(self, name: str) -> Any:
        return getattr(self._lib, "E57_DOUBLE" if name == "E57_SINGLE" else name)


@contextlib.contextmanager
def _double_coordinates() -> Iterator[None]:
    """pye57's writer with double-precision point fields, for the time of one write."""
    import pye57.e57 as module

    with _DOUBLE_LOCK:
        lib = module.libe57
        module.libe57 = _DoublePrecision(lib)  # type: ignore[assignment]
        try:
            yield
        finally:
            module.libe57 = lib


def write_e57(plain: PlainDocument, out: BinaryIO) -> None:
    """Write a plain document as E57 (see the module docstring)."""
    import pye57

    fd, name = tempfile.mkstemp(suffix=".e57", prefix="geosmooth-")
    os.close(fd)
    os.unlink(name)
    try:
        e57 = pye57.E57(name, mode="w")
        double = plain.coordinate_dtype() != np.float32
        with _double_coordinates() if double else contextlib.nullcontext():
            for scan_name, rot, trans, data in _scans_of(plain):
                e57.write_scan_raw(data, name=scan_name, rotation=rot, translation=trans)
        e57.close()
        with open(name, "rb") as fh:
            while chunk := fh.read(1 << 20):
                out.write(chunk)
    finally:
        if os.path.exists(name):
            os.unlink(name)
