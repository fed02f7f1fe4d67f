"""Format dispatch: :func:`read_geometry`, :func:`write_geometry`, :func:`save_geometry`.

Every format is an entry of :data:`~service.io.registry.FORMATS`; the format of an input comes
from the explicit name, else the file name's extension, else the content (magic numbers, then
the text formats' first lines). Writers get the plain document of :mod:`service.io._shared.plain`.

What a format can hold is data of the registry (``kinds``, ``geographic_only``, ``max_dims``,
``attributes``, ``coordinates``); :func:`check_output` is the one place that checks a document
against it, used by the CLI and the API before smoothing and by every write.
"""

from __future__ import annotations

import contextlib
import io
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
from numpy.typing import ArrayLike

from service.io._shared.plain import NormalsMode, PrecisionMode, WriteOptions, plain_document
from service.io.document import GeometryDocument
from service.io.errors import FormatError, UnsupportedFormat
from service.io.holds import (
    dropped_kinds,
    georeference,
    input_kinds,
    is_geographic,
    output_notes,
    same_family,
)
from service.io.limits import InputTooLarge, ReadLimits, reading
from service.io.registry import (
    FORMATS,
    Format,
    format_for_name,
    get_format,
    sniff,
    supported_text,
)
from service.io.source import Source

__all__ = [
    "FORMATS",
    "OutputRefused",
    "check_not_empty",
    "check_output",
    "detect_format",
    "formats_for",
    "input_kinds",
    "is_geographic",
    "output_notes",
    "read_geometry",
    "save_geometry",
    "sniff_format",
    "write_geometry",
]

SourceLike = bytes | bytearray | memoryview | str | os.PathLike[str] | Source


def detect_format(filename: str) -> str:
    """The format of a file from its name's extension (case-insensitive).

    Raises
    ------
    UnsupportedFormat
        For unknown extensions and names without one.
    """
    name = Path(str(filename)).name
    suffix = Path(name).suffix.lower().lstrip(".")
    if not suffix:
        raise UnsupportedFormat(
            f"cannot tell the format of {name!r} (no file extension): {supported_text()};"
            " pass the format explicitly"
        )
    known = format_for_name(name)
    if known is None:
        raise UnsupportedFormat(
            f"unsupported file extension '.{suffix}' ({name!r}): {supported_text()}", fmt=suffix
        )
    return known.name


def sniff_format(data: bytes, size: int | None = None) -> str | None:
    """Guess the format from the content (the first bytes suffice), or ``None``."""
    return sniff(bytes(data[:4096]), len(data) if size is None else size)


#: Formats marked binary whose header is text (their ascii bodies are, too).
_TEXT_HEADERS = frozenset({"ply", "pcd"})


def _resolve(source: Source, fmt: str | None, filename: str | None) -> str:
    name = str(filename or source.name or "")
    if fmt is not None:
        return get_format(fmt).name
    if Path(name).suffix:
        return detect_format(name)
    head = source.head(4096)
    sniffed = sniff(head, source.size)
    if sniffed is None:
        if not head.strip():
            raise FormatError("the file is empty")
        raise UnsupportedFormat(f"cannot tell the format of the data: {supported_text()}")
    return sniffed


def check_not_empty(src: Source, fmt: str) -> None:
    """:class:`FormatError` ``the file is empty`` (no bytes, or a little whitespace)."""
    if src.size == 0 or (src.size <= 4096 and not src.head().strip()):
        raise FormatError("the file is empty", fmt=fmt)


def read_geometry(
    source: SourceLike,
    fmt: str | None = None,
    *,
    filename: str | None = None,
    weld: bool | None = None,
    limits: ReadLimits | None = None,
    **options: Any,
) -> GeometryDocument:
    """Read a geometry file.

    Parameters
    ----------
    source : bytes or str or path-like
        File content (e.g. an upload) or a path (big files are then streamed where the format
        allows it).
    fmt : str, optional
        A name of :data:`FORMATS`. Default: from the extension of ``filename`` (or the path's
        name); without one, from the content.
    filename : str, optional
        Name used to detect the format of bytes.
    weld : bool, optional
        Merge exactly coincident vertices (see :mod:`service.io._shared.weld`); writers still
        write the file's vertex count and order. Default: the format's (STL and GLB: yes); other
        formats weld when duplicate positions tie faces (a mesh stored one vertex per position
        and normal would otherwise tear apart when smoothed; issue 31).
    limits : ReadLimits, optional
        Points a file may hold and memory its reading may take, checked from the declared
        counts before anything is allocated (:mod:`service.io.limits`; default: the limits in
        force, else ``ReadLimits()``: 1e9 points, 3/4 of the machine's memory).
    **options
        Reader options of the format (``xyz_dims`` for XYZ, ``geographic`` for GPX/GeoJSON);
        options given as ``None`` are ignored.

    Raises
    ------
    UnsupportedFormat
        A format geosmooth does not read.
    InputTooLarge
        More points, or a larger memory estimate, than ``limits`` allow (a ``FormatError``).
    FormatError
        A malformed file (one-line message; the line number for text formats).
    GeometryError
        Content with no meaning as smoothing input (e.g. non-finite coordinates).
    ValueError
        A reader option the format does not understand.
    """
    src = Source.of(source)
    bare = src.without_bom()  # text formats: a UTF-8 BOM is not content
    spec = FORMATS[_resolve(bare, fmt, filename)]
    if not spec.binary or spec.name in _TEXT_HEADERS:
        src = bare
    check_not_empty(src, spec.name)
    given = _reader_options(spec, options)
    do_weld = spec.weld_default if weld is None else bool(weld)
    with reading(limits) as bounds, parser_failures(spec.name):
        doc: GeometryDocument = spec.read(src, weld=do_weld, **given)
        bounds.check(int(doc.geometry.n), 0, spec.name)  # formats without a declared count
    if weld is None and not do_weld:
        from service.io._shared.weld import weld_if_tied

        doc = weld_if_tied(doc)
    return doc


@contextlib.contextmanager
def parser_failures(fmt: str) -> Iterator[None]:
    """Failures of a third-party parser on a hostile file as the file's error (issue 42).

    ``MemoryError`` while reading is :class:`InputTooLarge`; an overflow, a linear-algebra
    failure or an assertion inside a parser (a 400-digit integer, ezdxf's audit) is a
    :class:`FormatError` line, never an internal error.
    """
    try:
        yield
    except MemoryError:
        raise InputTooLarge(
            f"reading the file ran out of memory; {ReadLimits.HINT}", fmt=fmt
        ) from None
    except (OverflowError, np.linalg.LinAlgError, AssertionError) as exc:
        text = " ".join(str(exc).split())[:200]
        raise FormatError(
            f"{fmt}: the file could not be parsed ({type(exc).__name__}: {text})", fmt=fmt
        ) from None


def _reader_options(spec: Format, options: dict[str, Any]) -> dict[str, Any]:
    """The options given (not ``None``); ``ValueError`` for one ``spec``'s reader lacks."""
    given = {k: v for k, v in options.items() if v is not None}
    for key in given:
        if key not in spec.options:
            users = [f.title for f in FORMATS.values() if key in f.options] or ["no"]
            raise ValueError(f"{key} applies to {' and '.join(users)} files only")
    return given


def _plain(
    doc: GeometryDocument,
    points: ArrayLike | None,
    normals: NormalsMode,
    precision: PrecisionMode,
    ply_ascii: bool | None,
) -> Any:
    options = WriteOptions(normals=normals, precision=precision, ply_ascii=ply_ascii)
    return plain_document(doc, points, options)


def write_geometry(
    doc: GeometryDocument,
    fmt: str,
    points: ArrayLike | None = None,
    *,
    ply_ascii: bool | None = None,
    normals: NormalsMode = "recompute",
    precision: PrecisionMode = "input",
    crs: str | int | None = None,
) -> bytes:
    """Write a document (optionally with new points) in one of :data:`FORMATS`.

    Parameters
    ----------
    doc : GeometryDocument
        From :func:`read_geometry` (or built from a geometry).
    fmt : str
        Output format.
    points : array_like, optional
        The smoothed points, shaped like ``doc.geometry.points`` (default: the doc's own). A
        welded document is written with the input's vertex count, order and connectivity.
    ply_ascii : bool, optional
        PLY: ASCII (True), binary little-endian (False), the input's encoding (None).
    normals : {"recompute", "drop"}
        Input normals recomputed from the written geometry, or left out.
    precision : {"input", "float32", "float64"}
        Coordinates as the input stored them (dtype; digits for text formats) or forced.
    crs : str or int, optional
        Geographic input (GPX, GeoJSON) written to a projected format: the projected CRS of the
        output, an EPSG code (``32633``, ``"EPSG:32633"``) or ``"utm"`` (the WGS84 UTM zone of
        the data's centre); easting, northing and the elevation as read. Default: metres in the
        local east/north/up frame about the data's centre. Either way the frame is recorded in
        the formats that hold one (:mod:`service.io._shared.georef`).

    Raises
    ------
    FormatError
        The format cannot hold the data (e.g. PLY and OBJ: 2 or 3 coordinates).
    UnsupportedFormat
        ``fmt`` is not one of :data:`FORMATS`.
    ValueError
        ``points`` has the wrong shape, or a bad option (``crs`` for input that is not
        geographic, or a CRS that is not projected).
    """
    out = io.BytesIO()
    save_geometry(
        doc, out, fmt, points, ply_ascii=ply_ascii, normals=normals, precision=precision, crs=crs
    )
    return out.getvalue()


def save_geometry(
    doc: GeometryDocument,
    dest: str | os.PathLike[str] | BinaryIO,
    fmt: str | None = None,
    points: ArrayLike | None = None,
    *,
    ply_ascii: bool | None = None,
    normals: NormalsMode = "recompute",
    precision: PrecisionMode = "input",
    crs: str | int | None = None,
) -> None:
    """Like :func:`write_geometry`, streamed to a path or binary file (no whole-file copy).

    ``fmt`` defaults to the path's extension, else the document's source format. A path is
    written in place (atomic replacement is the caller's business).
    """
    if fmt is None:
        named = format_for_name(str(dest)) if isinstance(dest, str | os.PathLike) else None
        fmt = named.name if named is not None else doc.source_format
    spec = get_format(fmt)
    check_output(doc, spec.name, points)
    plain = georeference(doc, spec, _plain(doc, points, normals, precision, ply_ascii), crs)
    if isinstance(dest, str | os.PathLike):
        with open(dest, "wb") as fh:
            spec.write_to(plain, fh)
    else:
        spec.write_to(plain, dest)


class OutputRefused(FormatError):
    """The output format cannot hold this input; the message names the formats that can."""

    code = "output-format-refused"
    field = "format"
    title = "Output format cannot hold this input"
    status = 422
    exit_code = 6  # the CLI's table (service/exit_codes.py): cannot write the output


_KIND_WORDS = {"mesh": "faces", "polyline": "lines", "cloud": "a point cloud"}


def _float32_loss(doc: GeometryDocument, spec: Format, points: ArrayLike | None) -> float:
    """Half a float32 step at the coordinates ``spec`` stores, if that loses input precision.

    0 when nothing the input had is lost: the input was float32, or the step stays within
    1e-6 of the extent and the input's own resolution (its decimals, for text input).
    """
    import numpy as np

    if spec.coordinates == "float64" or np.dtype(doc.precision.dtype) == np.float32:
        return 0.0
    pts = np.asarray(doc.geometry.points if points is None else points, dtype=np.float64)
    if not pts.size:
        return 0.0
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    if spec.coordinates == "float32-offset":
        pts = pts - (lo + hi) / 2
    half = float(np.spacing(np.float32(np.max(np.abs(pts))))) / 2
    allowed = 1e-6 * float(np.max(hi - lo))
    for spec_text in doc.precision.text or ():
        if spec_text.startswith("%.") and spec_text.endswith("f"):
            allowed = max(allowed, 0.5 * 10.0 ** -int(spec_text[2:-1]))
    return half if half > allowed else 0.0


def _problem(doc: GeometryDocument, spec: Format, points: ArrayLike | None = None) -> str | None:
    """Why ``spec`` cannot hold ``doc`` (``None``: it can)."""
    if same_family(doc, spec):
        return None
    missing = sorted(input_kinds(doc) - spec.kinds - set(dropped_kinds(doc, spec)))
    if missing:
        held = " or ".join(_KIND_WORDS[k] for k in sorted(spec.kinds))
        return f"{spec.title} holds {held}, not {_KIND_WORDS[missing[0]]}"
    dim = doc.geometry.dim
    if dim < spec.min_dims or (spec.max_dims is not None and dim > spec.max_dims):
        most = "any number of" if spec.max_dims is None else f"at most {spec.max_dims}"
        return (
            f"{spec.title} stores at least {spec.min_dims} and {most} coordinates per point; "
            f"this geometry has {dim} coordinates per point"
        )
    if spec.geographic_only and not is_geographic(doc):
        return (
            f"{spec.title} holds longitude/latitude, and this {doc.source_format.upper()} input "
            "has planar coordinates (read it from GPX or GeoJSON to write it there)"
        )
    loss = _float32_loss(doc, spec, points)
    if loss:
        return (
            f"{spec.title} stores float32 coordinates, which would move these points by up to "
            f"{loss:.3g} (more than the input's precision)"
        )
    return None


def formats_for(doc: GeometryDocument) -> list[str]:
    """The writable formats that hold ``doc`` whole, in registry order (not the point formats
    that would write a mesh's or a polyline's vertices only)."""
    return [
        f.name
        for f in FORMATS.values()
        if f.write is not None and _problem(doc, f) is None and not dropped_kinds(doc, f)
    ]


def check_output(doc: GeometryDocument, fmt: str, points: ArrayLike | None = None) -> None:
    """Refuse an output format that cannot hold ``doc`` (before smoothing, and at every write).

    Raises
    ------
    OutputRefused
        One line: why, and the formats that can hold this input.
    UnsupportedFormat
        ``fmt`` is not a writable format.
    """
    spec = get_format(fmt)
    why = _problem(doc, spec, points)
    if why is not None:
        can = ", ".join(formats_for(doc))
        tail = f"write {can} instead" if can else "no format geosmooth writes can hold it"
        raise OutputRefused(f"cannot write {spec.name}: {why}; {tail}", fmt=spec.name)
