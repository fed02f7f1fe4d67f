"""PCD (Point Cloud Library): ``DATA ascii``, ``binary`` and ``binary_compressed``.

Our own header and body reader on numpy, with python-neo-lzf (the LZF binding pypcd4 uses) for
``binary_compressed``: pypcd4 skips header lines it does not understand, renames ``_`` padding
fields at random, writes ASCII floats with ``%.10f`` (neither round-trip exact nor the input's
digits) and gives no line numbers; the tests check that pypcd4 reads what we write.

Reading
-------
* The header (``VERSION FIELDS SIZE TYPE COUNT WIDTH HEIGHT VIEWPOINT POINTS DATA``) is checked
  line by line; a field of ``COUNT k > 1`` is an attribute of shape ``(n, k)``.
* Points whose ``x, y`` or ``z`` is NaN (the invalid pixels of an organised cloud) are left out
  of the geometry and written back in place, unchanged, so ``WIDTH x HEIGHT`` survives.
* ``normal_x normal_y normal_z`` are the normals (recomputed on write); every other field
  (``rgb`` packed floats bit for bit, ``intensity``, ``label``, ``curvature``, ``_`` padding,
  ...) is an attribute in its own dtype. Binary bodies are views of the input (no copy).

Writing
-------
The input's header and encoding, every record as read except new coordinates and normals; ASCII
values with the input's digits. Other documents (:mod:`.pcd_export`): ``x y z``, normals,
numeric attributes as fields; ``DATA binary`` with float32 coordinates when float32 keeps the
input's precision, else ``DATA ascii`` with doubles (Open3D reads binary ``F 8`` as zeros).
Colours ``red green blue [alpha]`` (PLY, XYZ, E57, LAS) become PCL's packed field ``rgb`` (or
``rgba`` with alpha), which PCL, Open3D and pypcd4 read as colours. Channels are 8-bit: values
above 255 (16-bit LAS colours) are scaled by 255/65535, float channels in [0, 1] by 255.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass
from typing import Any, BinaryIO

import numpy as np
from numpy.typing import NDArray

from service.io._shared.assemble import assemble
from service.io._shared.numfmt import Digits, default_spec, write_rows
from service.io._shared.plain import PlainDocument
from service.io._shared.text import LineBlock, line_blocks, table_rows
from service.io.document import GeometryDocument, Precision
from service.io.errors import FormatError
from service.io.limits import check_points
from service.io.source import Source

__all__ = ["PcdLayout", "read_pcd", "write_pcd"]

_KEYS = ("VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS",
         "DATA")  # fmt: skip
_NORMALS = ("normal_x", "normal_y", "normal_z")
_TYPES = {(k, s): f"{k.lower()}{s}" for k in "UI" for s in (1, 2, 4, 8)}
_TYPES |= {("F", 4): "f4", ("F", 8): "f8"}


@dataclass(frozen=True, eq=False)
class PcdLayout:
    """Header lines, the records as read, which of them are in the geometry."""

    header: list[str]
    encoding: str
    records: NDArray[Any]
    valid: NDArray[np.bool_] | None
    specs: dict[str, str]


def _fail(message: str, line: int | None = None) -> FormatError:
    where = f"line {line}: " if line is not None else ""
    return FormatError(f"PCD {where}{message}", fmt="pcd", line=line)


def _header(data: bytes) -> tuple[dict[str, list[str]], list[str], int, int]:
    """Header fields, header lines (comments included), body offset, lines read."""
    fields: dict[str, list[str]] = {}
    lines: list[str] = []
    pos = number = 0
    while pos < len(data) and "DATA" not in fields:
        nl = data.find(b"\n", pos)
        if nl < 0:
            raise _fail("the header has no 'DATA' line")
        raw = data[pos:nl].decode("ascii", errors="replace").strip()
        pos = nl + 1
        number += 1
        lines.append(raw)
        if not raw or raw.startswith("#"):
            continue
        key, *values = raw.split()
        if key not in _KEYS:
            raise _fail(f"unknown header keyword {key[:20]!r}", number)
        if key in fields:
            raise _fail(f"{key} given twice", number)
        fields[key] = values
    for key in ("DATA", "FIELDS", "SIZE", "TYPE", "POINTS"):
        if key not in fields:
            raise _fail(f"the header has no {key} line")
    return fields, lines, pos, number


def _dtype(fields: dict[str, list[str]]) -> np.dtype[Any]:
    names, sizes, types = fields["FIELDS"], fields["SIZE"], fields["TYPE"]
    counts = fields.get("COUNT", ["1"] * len(names))
    if not len(names) == len(sizes) == len(types) == len(counts):
        raise _fail("FIELDS, SIZE, TYPE and COUNT must have the same number of entries")
    out: list[Any] = []
    seen: dict[str, int] = {}
    for name, size, kind, count in zip(names, sizes, types, counts, strict=True):
        try:
            code = _TYPES[(kind, int(size))]
            k = int(count)
        except (KeyError, ValueError):
            raise _fail(f"field {name!r}: unsupported TYPE {kind} SIZE {size}") from None
        if k < 1:
            raise _fail(f"field {name!r}: COUNT must be positive")
        seen[name] = seen.get(name, 0) + 1
        key = name if seen[name] == 1 else f"{name}#{seen[name]}"  # e.g. several "_" paddings
        out.append((key, "<" + code, (k,)) if k > 1 else (key, "<" + code))
    return np.dtype(out)


def _body(data: bytes, pos: int, encoding: str, dt: np.dtype[Any], n: int) -> Any:
    if encoding == "binary":
        if pos + n * dt.itemsize > len(data):
            raise _fail(f"binary body truncated: {n} points need {n * dt.itemsize} bytes")
        return np.frombuffer(data, dtype=dt, count=n, offset=pos), None
    if encoding == "binary_compressed":
        import lzf

        if pos + 8 > len(data):
            raise _fail("binary_compressed body truncated")
        csize, usize = struct.unpack("<II", data[pos : pos + 8])
        if usize != n * dt.itemsize or pos + 8 + csize > len(data):
            raise _fail(f"binary_compressed sizes ({csize}, {usize}) do not match {n} points")
        try:
            raw = lzf.decompress(data[pos + 8 : pos + 8 + csize], usize) if usize else b""
        except (ValueError, SystemError):  # "error in compressed data"
            raw = None
        if raw is None or len(raw) != usize:
            raise _fail("binary_compressed body does not decompress (corrupt LZF data)")
        rec = np.empty(n, dtype=dt)
        at = 0
        for name in dt.names or ():
            size = dt[name].itemsize * n
            rec[name] = np.frombuffer(raw, dtype=dt[name], count=n, offset=at).reshape(
                rec[name].shape
            )
            at += size
        return rec, None
    if encoding != "ascii":
        raise _fail(f"unknown DATA encoding {encoding!r}")
    return _ascii(data, pos, dt, n)


def _ascii(data: bytes, pos: int, dt: np.dtype[Any], n: int) -> Any:
    width = sum(int(np.prod(dt[name].shape or (1,))) for name in dt.names or ())
    rec = np.empty(n, dtype=dt)
    digits = Digits(width)
    got = 0
    for block in line_blocks(data, pos, n):
        table = table_rows(
            LineBlock(block.data, block.offset, block.rows), data, width, fmt="pcd", what="a point"
        )
        digits.update(block.data, table)
        col = 0
        for name in dt.names or ():
            k = int(np.prod(dt[name].shape or (1,)))
            with np.errstate(over="ignore", invalid="ignore"):
                rec[name][got : got + len(table)] = table[:, col : col + k].reshape(
                    rec[name][got : got + len(table)].shape
                )
            col += k
        got += len(table)
    if got != n:
        raise _fail(f"the header declares {n} points but the body has {got}")
    return rec, digits


def read_pcd(source: Source, *, weld: bool = False) -> GeometryDocument:
    """Read a PCD file (see the module docstring)."""
    data = source.data()
    if not data.strip():
        raise FormatError("the file is empty", fmt="pcd")
    fields, lines, pos, _ = _header(data)
    dt = _dtype(fields)
    try:
        n = int(fields["POINTS"][0])
    except (IndexError, ValueError):
        raise _fail("POINTS must be a count") from None
    if n < 1:
        raise FormatError("the file holds no points", fmt="pcd")
    if fields["DATA"][0] != "ascii" and n * dt.itemsize > 64 * len(data) + 2**20:
        raise _fail(f"{n} points cannot come from a file of {len(data)} bytes")
    check_points(n, 24 + 2 * dt.itemsize, "pcd")  # coordinates + the record table (+ LZF)
    encoding = fields["DATA"][0] if fields["DATA"] else ""
    rec, digits = _body(data, pos, encoding, dt, n)
    names = list(dt.names or ())
    if not all(c in names for c in ("x", "y")):
        raise _fail("FIELDS has no x and y")
    coords = [c for c in ("x", "y", "z") if c in names]
    pts = np.empty((n, len(coords)))
    for j, c in enumerate(coords):
        pts[:, j] = rec[c]
    finite: NDArray[np.bool_] = np.asarray(np.isfinite(pts).all(axis=1))
    valid = None if finite.all() else finite
    sel = (lambda a: a) if valid is None else (lambda a: a[valid])
    specs: dict[str, str] = {}
    if digits is not None:
        flat_names = [nm for nm in names for _ in range(int(np.prod(dt[nm].shape or (1,))))]
        for nm, spec in zip(flat_names, digits.specs(), strict=True):
            specs.setdefault(nm, spec)
    normals = None
    if all(c in names for c in _NORMALS):
        normals = np.column_stack([sel(rec[c]) for c in _NORMALS])
    skip = set(coords) | (set(_NORMALS) if normals is not None else set())
    attributes = {nm: sel(rec[nm]) for nm in names if nm not in skip}
    notes = (
        []
        if valid is None
        else [
            f"left out {int((~finite).sum())} points with NaN coordinates (written back unchanged)"
        ]
    )
    layout = PcdLayout(lines, encoding, rec, valid, specs)
    cdt = "float32" if rec[coords[0]].dtype == np.float32 else "float64"
    precision = Precision(
        cdt,
        tuple(specs[c] for c in coords) if specs else None,
        {k: v for k, v in specs.items() if k in attributes},
    )
    doc = assemble(sel(pts), fmt="pcd", weld=weld, notes=notes)
    return doc.with_extras(
        attributes=attributes, normals=normals, precision=precision, layout=layout
    )


def _records(plain: PlainDocument, layout: PcdLayout) -> NDArray[Any]:
    rec = layout.records.copy()
    rows = slice(None) if layout.valid is None else layout.valid
    names = rec.dtype.names or ()
    coords = [c for c in ("x", "y", "z") if c in names]
    for j, c in enumerate(coords):
        col = rec[c].copy()
        col[rows] = plain.points[:, j]
        rec[c] = col
    if all(c in names for c in _NORMALS):
        for j, nc in enumerate(_NORMALS):
            col = rec[nc].copy()
            if plain.normals is not None:
                col[rows] = np.asarray(plain.normals[:, j])
            rec[nc] = col
    return rec


def _header_text(lines: list[str], encoding: str) -> bytes:
    out = [re.sub(r"^DATA\s+\S+", f"DATA {encoding}", ln) for ln in lines]
    return ("\n".join(out) + "\n").encode("ascii")


def write_pcd(plain: PlainDocument, out: BinaryIO) -> None:
    """Write a plain document as PCD (see the module docstring)."""
    layout = plain.layout
    n_valid = None
    if isinstance(layout, PcdLayout):
        n_valid = len(layout.records) if layout.valid is None else int(layout.valid.sum())
    if isinstance(layout, PcdLayout) and n_valid == plain.n and plain.dim <= 3:
        rec, lines, encoding = _records(plain, layout), layout.header, layout.encoding
        specs = dict(layout.specs)
        if plain.options.precision != "input" or not specs:
            specs = {}
        for j, c in enumerate(("x", "y", "z")[: plain.dim]):
            specs[c] = plain.coordinate_specs()[j]
    else:
        from service.io.formats.pcd_export import fresh_pcd

        rec, lines, encoding, specs = fresh_pcd(plain)
    if encoding == "binary_compressed":
        import lzf

        raw = b"".join(np.ascontiguousarray(rec[nm]).tobytes() for nm in rec.dtype.names or ())
        packed = lzf.compress(raw) if raw else b""
        if packed is None:  # incompressible: plain binary is smaller
            encoding = "binary"
        else:
            out.write(_header_text(lines, encoding))
            out.write(struct.pack("<II", len(packed), len(raw)) + packed)
            return
    out.write(_header_text(lines, encoding))
    if encoding == "binary":
        out.write(np.ascontiguousarray(rec).tobytes())
        return
    cols: list[tuple[NDArray[Any], str]] = []
    for nm in rec.dtype.names or ():
        values = rec[nm].reshape(len(rec), -1)
        for j in range(values.shape[1]):
            cols.append((values[:, j], specs.get(nm, default_spec(values.dtype))))
    write_rows(out, cols, n=len(rec))
