"""LAS and LAZ point clouds via laspy (LAZ through its lazrs backend), streamed in chunks.

Reading
-------
Every point format laspy knows (0-10). Points are read chunk by chunk
(``laspy.open(...).chunk_iterator``), so the file's record array is never held whole: the
document holds the float64 coordinates (``X * scale + offset``) and every other dimension
(intensity, return and class bits, classification, scan angle, user data, point source id, GPS
time, RGB, NIR, waveform fields, extra bytes) as an attribute in its own dtype. The header
(version, point format, scales, offsets, VLRs, EVLRs) is the layout.

Writing
-------
A document read from LAS/LAZ is written by streaming the input again: each chunk keeps every
dimension as it was, bit for bit, and gets new ``X, Y, Z`` from the smoothed coordinates with
the file's own scale and offset (``round((x - offset) / scale)``); a coordinate that no longer
fits the 32-bit integers of that scale and offset is a :class:`FormatError` saying so. The header
bounds are recomputed. Other documents get a new header: point format 0-3 (by whether they carry
``gps_time`` and ``red green blue``), a scale of ``10^k`` with ``k`` from the input's precision
(at most ``1e-7`` of the extent), intensity/classification/... taken from attributes of those
names (8-bit colours scaled to LAS's 16 bits, x 257) and the other numeric attributes as extra
bytes.
"""

from __future__ import annotations

import contextlib
import logging
import math
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any, BinaryIO

import numpy as np
from numpy.typing import NDArray

from service.io._shared.assemble import assemble
from service.io._shared.coords import as_xyz
from service.io._shared.plain import PlainDocument
from service.io.document import GeometryDocument, Precision
from service.io.errors import FormatError, MissingDependency
from service.io.formats.laz_chunks import check_chunk_table
from service.io.limits import check_points
from service.io.source import Source

__all__ = [
    "LasLayout", "LasPoints", "open_points", "read_las", "read_laz", "write_las", "write_laz",
]  # fmt: skip

CHUNK = 1 << 20
_COORDS = ("X", "Y", "Z")


@dataclass(frozen=True, eq=False)
class LasLayout:
    """The input's header and where to stream its points from again."""

    header: Any  # laspy.LasHeader
    source: Source
    compressed: bool


#: laspy logs a read error before raising it; the raised error becomes one FormatError line
#: (:func:`_laspy_errors`), so its log record would only repeat it on the user's stderr.
logging.getLogger("laspy").setLevel(logging.CRITICAL)


@contextlib.contextmanager
def _laspy_errors(fmt: str) -> Any:
    try:
        yield
    except FormatError:
        raise
    except MemoryError:
        raise
    except ImportError as exc:  # the server's installation, not the file (issue 41)
        raise MissingDependency.of(exc, fmt) from exc
    except Exception as exc:  # laspy and lazrs raise many kinds on bad files; report one line
        text = " ".join(str(exc).split())[:200] or type(exc).__name__
        raise FormatError(f"{fmt.upper()}: {text}", fmt=fmt) from None
    except BaseException as exc:  # a Rust panic in lazrs (pyo3's PanicException) is not an
        if type(exc).__name__ != "PanicException":  # Exception; any other BaseException is
            raise  # KeyboardInterrupt, SystemExit ...
        raise FormatError(f"{fmt.upper()}: the decoder failed ({exc})", fmt=fmt) from None


def _check_version(header: Any, fmt: str) -> None:
    """A point format the file's LAS version cannot hold is malformed at the read (it was
    smoothed, then refused by the writer: exit 6 instead of 3)."""
    from laspy.point import dims

    version, point_format = str(header.version), int(header.point_format.id)
    if not dims.is_point_fmt_compatible_with_version(point_format, version):
        raise FormatError(
            f"{fmt.upper()}: malformed header: point format {point_format} does not exist in"
            f" LAS {version}",
            fmt=fmt,
        )


def _decimals(scale: float) -> int | None:
    if not (math.isfinite(scale) and scale > 0):
        return None
    k = -np.log10(scale)
    return round(k) if scale > 0 and abs(k - round(k)) < 1e-9 and round(k) >= 0 else None


def _precheck(head: bytes, size: int, fmt: str) -> None:
    """Counts of the public header block that laspy would trust (and loop over) must fit."""
    header_size, offset, n_vlrs = struct.unpack_from("<HII", head, 94)
    problem = None
    if not 227 <= header_size <= offset <= size:
        problem = f"header size {header_size} / point data offset {offset} outside the file"
    elif n_vlrs * 54 > offset - header_size:
        problem = f"{n_vlrs} VLRs cannot fit in {offset - header_size} bytes"
    elif head[25] >= 4 and len(head) >= 247:  # LAS 1.4: extended VLRs at the end
        start, n_evlrs = struct.unpack_from("<QI", head, 235)
        if n_evlrs and (start > size or n_evlrs * 60 > size - start):
            problem = f"{n_evlrs} extended VLRs cannot fit after byte {start}"
    if problem is None and len(head) >= 179:
        scales = zip("xyz", struct.unpack_from("<3d", head, 131), strict=True)
        offsets = zip("xyz", struct.unpack_from("<3d", head, 155), strict=True)
        bad = [f"{a} scale {v!r}" for a, v in scales if not math.isfinite(v) or v == 0]
        bad += [f"{a} offset {v!r}" for a, v in offsets if not math.isfinite(v)]
        if bad:  # every coordinate would be the offset, or NaN
            problem = f"{', '.join(bad)} (scales must be finite and non-zero)"
    if problem is not None:
        raise FormatError(f"{fmt.upper()}: malformed header: {problem}", fmt=fmt)


def _check_count(header: Any, n: int, size: int, fmt: str) -> None:
    """The declared point count must fit the file (no allocation from an absurd header)."""
    record = int(header.point_format.size)
    room = size - int(header.offset_to_point_data)
    limit = room if not header.are_points_compressed else 1000 * max(room, 0)
    if n * record > limit:
        raise FormatError(
            f"{fmt.upper()}: the header declares {n} points of {record} bytes but the file has"
            f" {max(room, 0)} bytes of point data",
            fmt=fmt,
        )


@contextlib.contextmanager
def open_points(source: Source, fmt: str, *, attributes: bool = True) -> Iterator[LasPoints]:
    """The checked point stream of a LAS/LAZ file, for the ordinary reader and the streamed one.

    Before anything is allocated: the file is long enough for a header, the header's sizes,
    VLR counts, scales and offsets are sane (:func:`_precheck`), it holds points, the declared
    count fits the file (:func:`_check_count`) and the reader limits
    (:func:`service.io.limits.check_points`; ``attributes``: the other dimensions are kept
    too). While iterating: no more and no fewer points than declared. Every laspy/lazrs error is
    one :class:`FormatError` line.
    """
    import laspy

    if source.size == 0:
        raise FormatError("the file is empty", fmt=fmt)
    if source.size < 227:
        raise FormatError(f"{fmt.upper()}: the file is too short for a LAS header", fmt=fmt)
    _precheck(source.head(375), source.size, fmt)
    check_chunk_table(source, fmt)
    # lazrs' sequential decoder: the parallel one trusts every chunk table entry (a damaged
    # one made it panic, "capacity overflow"); the sequential one reads the chunks in turn
    backend = laspy.LazBackend.Lazrs
    with (
        _laspy_errors(fmt),
        source.open() as fh,
        laspy.open(fh, closefd=False, laz_backend=backend) as reader,
    ):
        header = reader.header
        _check_version(header, fmt)
        n = int(header.point_count)
        if n == 0:
            raise FormatError("the file holds no points", fmt=fmt)
        _check_count(header, n, source.size, fmt)
        record = int(header.point_format.size)
        check_points(n, 24 + (2 * record if attributes else 0), fmt)
        yield LasPoints(header, n, _checked_chunks(reader, n, fmt))


@dataclass(frozen=True)
class LasPoints:
    """A LAS/LAZ file's header, declared point count and checked chunks (:func:`open_points`)."""

    header: Any
    n: int
    chunks: Iterator[Any]


def _checked_chunks(reader: Any, n: int, fmt: str) -> Iterator[Any]:
    at = 0
    for chunk in reader.chunk_iterator(CHUNK):
        at += len(chunk)
        if at > n:
            raise FormatError(f"{fmt.upper()}: more points than the header declares", fmt=fmt)
        yield chunk
    if at != n:
        raise FormatError(
            f"{fmt.upper()}: the header declares {n} points but the file holds {at}", fmt=fmt
        )


def _read(source: Source, fmt: str, weld: bool) -> GeometryDocument:
    with open_points(source, fmt) as stream:
        header, n = stream.header, stream.n
        names = [d for d in header.point_format.dimension_names if d not in _COORDS]
        points = np.empty((n, 3))
        attrs: dict[str, NDArray[Any]] = {}
        at = 0
        for chunk in stream.chunks:
            k = len(chunk)
            points[at : at + k, 0] = chunk.x
            points[at : at + k, 1] = chunk.y
            points[at : at + k, 2] = chunk.z
            for name in names:
                col = np.asarray(chunk[name])
                if name not in attrs:
                    attrs[name] = np.empty((n, *col.shape[1:]), dtype=col.dtype)
                attrs[name][at : at + k] = col
            at += k
    decimals = [_decimals(float(s)) for s in header.scales]
    text = tuple(f"%.{d}f" for d in decimals) if None not in decimals else None
    layout = LasLayout(header, source, fmt == "laz" or header.are_points_compressed)
    doc = assemble(points, fmt=fmt, weld=weld)
    notes = [
        f"LAS {header.version} point format {header.point_format.id},"
        f" {len(names) + 3} dimensions kept"
    ]
    return doc.with_extras(
        attributes=attrs, precision=Precision("float64", text), layout=layout, notes=notes
    )


def read_las(source: Source, *, weld: bool = False) -> GeometryDocument:
    """Read a LAS file (see the module docstring)."""
    return _read(source, "las", weld)


def read_laz(source: Source, *, weld: bool = False) -> GeometryDocument:
    """Read a LAZ file (see the module docstring)."""
    return _read(source, "laz", weld)


def _scaled(values: NDArray[np.float64], scale: float, offset: float, axis: str) -> Any:
    q = np.round((values - offset) / scale)
    lo, hi = float(q.min()), float(q.max())
    if lo < -(2**31) or hi > 2**31 - 1 or not np.isfinite(q).all():
        bad = values[np.argmax(np.abs(q))]
        raise FormatError(
            f"the smoothed {axis} coordinate {bad!r} no longer fits the file's scale {scale!r}"
            f" and offset {offset!r} (32-bit integers); write another format or a new header",
            fmt="las",
        )
    return q.astype(np.int32)


def _restream(plain: PlainDocument, layout: LasLayout, out: BinaryIO, compress: bool) -> None:
    import laspy

    pts = plain.points
    header = layout.header if plain.georef is None else _reprojected(layout.header, plain)
    with (
        _laspy_errors("las"),
        layout.source.open() as fh,
        laspy.open(fh, closefd=False) as reader,
        laspy.open(out, mode="w", header=header, do_compress=compress, closefd=False) as writer,
    ):
        at = 0
        for chunk in reader.chunk_iterator(CHUNK):
            k = len(chunk)
            if header is not layout.header:  # new offsets: the record scaled by the new header
                chunk = laspy.ScaleAwarePointRecord(
                    chunk.array, header.point_format, header.scales, header.offsets
                )
            if "classification" in plain.attributes:  # outliers flagged as class 7 (issue 31)
                chunk["classification"] = plain.attributes["classification"][at : at + k]
            if plain.moved:
                for j, name in enumerate(_COORDS):
                    scale, offset = float(header.scales[j]), float(header.offsets[j])
                    chunk[name] = _scaled(pts[at : at + k, j], scale, offset, "xyz"[j])
            writer.write_points(chunk)
            at += k
        if header.evlrs:
            writer.write_evlrs(header.evlrs)


def _reprojected(header: Any, plain: PlainDocument) -> Any:
    """The input's header for the reprojected points of ``plain`` (:mod:`.las_meta`)."""
    import pyproj

    from service.io.formats.las_meta import reprojected_header

    crs = pyproj.CRS.from_user_input(plain.georef.crs)
    return reprojected_header(header, crs, as_xyz(plain.points, "las"))


def _new_header(plain: PlainDocument) -> Any:
    import laspy

    attrs = plain.attributes
    rgb = all(c in attrs for c in ("red", "green", "blue"))
    fmt_id = (2 if rgb else 0) + (1 if "gps_time" in attrs else 0)
    header = laspy.LasHeader(point_format=fmt_id, version="1.2")
    if plain.georef is not None:  # a WKT VLR needs LAS 1.4 and point format 6 or 7
        from laspy.vlrs.known import WktCoordinateSystemVlr

        header = laspy.LasHeader(point_format=7 if rgb else 6, version="1.4")
        header.vlrs.append(WktCoordinateSystemVlr(plain.georef.wkt()))
        header.global_encoding.wkt = True
    pts = as_xyz(plain.points, "las")
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    extent = float(np.max(hi - lo)) or max(float(np.max(np.abs(pts))), 1.0)
    specs = plain.coordinate_specs()
    decimals = []
    for spec in specs[:3]:
        d = int(spec[2:-1]) if spec.endswith("f") and spec.startswith("%.") else 9
        decimals.append(min(d, int(np.ceil(-np.log10(1e-7 * extent)))))
    header.scales = np.array([10.0**-d for d in decimals])
    header.offsets = np.floor(lo)
    known = set(header.point_format.dimension_names)
    for name, values in attrs.items():
        if name not in known and values.ndim == 1 and values.dtype.kind in "iuf":
            header.add_extra_dim(laspy.ExtraBytesParams(name=name, type=values.dtype))
    return header, pts


def _fresh(plain: PlainDocument, out: BinaryIO, compress: bool) -> None:
    import laspy

    header, pts = _new_header(plain)
    names = set(header.point_format.dimension_names)
    with (
        _laspy_errors("las"),
        laspy.open(out, mode="w", header=header, do_compress=compress, closefd=False) as writer,
    ):
        for s in range(0, plain.n, CHUNK):
            rec = laspy.ScaleAwarePointRecord.zeros(min(CHUNK, plain.n - s), header=header)
            for j, name in enumerate(_COORDS):
                rec[name] = _scaled(
                    pts[s : s + len(rec), j],
                    float(header.scales[j]),
                    float(header.offsets[j]),
                    "xyz"[j],
                )
            for name, values in _colours16(plain.attributes).items():
                if name in names and name not in _COORDS and values.ndim == 1:
                    rec[name] = values[s : s + len(rec)]
            writer.write_points(rec)


def _colours16(attrs: dict[str, NDArray[Any]]) -> dict[str, NDArray[Any]]:
    """The attributes, with 8-bit ``red green blue`` scaled to LAS's 16 bits (x 257: 255 ->
    65535; the LAS 1.4 specification: RGB "should always be normalized to 16 bit values")."""
    names = ("red", "green", "blue")
    if not all(c in attrs and attrs[c].dtype.kind in "iuf" and attrs[c].size for c in names):
        return attrs
    values = np.concatenate([np.asarray(attrs[c], dtype=np.float64).ravel() for c in names])
    top = float(values.max())
    if not (1.0 < top <= 255.0 and values.min() >= 0 and np.all(values == np.round(values))):
        return attrs
    scaled = {c: (np.asarray(attrs[c]) * 257).astype(np.uint16) for c in names}
    return {**attrs, **scaled}


def _write(plain: PlainDocument, out: BinaryIO, compress: bool) -> None:
    layout = plain.layout
    if isinstance(layout, LasLayout) and int(layout.header.point_count) == plain.n:
        _restream(plain, layout, out, compress)
    else:
        _fresh(plain, out, compress)


def write_las(plain: PlainDocument, out: BinaryIO) -> None:
    """Write a plain document as LAS (see the module docstring)."""
    _write(plain, out, False)


def write_laz(plain: PlainDocument, out: BinaryIO) -> None:
    """Write a plain document as LAZ (see the module docstring)."""
    _write(plain, out, True)
