"""The use case read -> smooth -> write, written once.

Every caller that turns an input file into a smoothed file goes through :func:`smooth_file`:
the CLI (``geosmooth smooth``), the job runner (:func:`service.jobs.runner.smooth_job`), the
synchronous endpoint (``POST /v1/smooth``) and the library facade (:mod:`geosmooth`). It runs
one of two paths:

* **streamed** (:func:`smooth_streamed`): a tiled run of a LAS/LAZ, binary PLY or XYZ file
  written in its own format without options: only the coordinates are read
  (:func:`service.io.stream.read_coordinates`) and the file is streamed again with the new ones
  (:func:`service.io.stream.rewrite`), so the attribute table never sits in memory;
* **in memory** (:func:`smooth_document`): the whole document, the output format checked before
  smoothing (:func:`service.io.dispatch.check_output`), the result encoded by
  :func:`service.io.write_geometry`.

The engine is entered through :func:`run_engine` only (:func:`service.core.smooth`). A file
target is written atomically (:func:`service.io.atomic.atomic_path`: the old file or the new
one, never half of it, on either path); a callable target (:data:`Store`) takes the result and
its bytes (stdout, a job directory, a spool file). Errors are mapped here, once: a file format
that cannot hold the smoothed points is an :class:`OutputFormatError` (a
:class:`~service.io.errors.FormatError`, so HTTP and job answers are those of the format error;
the CLI answers it as an output failure); every other typed error of the readers and the
engine propagates as raised.

**Unchanged is byte-identical** (issue 32): when the engine returns the input's points bit for
bit (no noise found, every point fixed, nothing coupled, no valid budget: whatever the reason,
:func:`returned_unchanged` compares the points), nothing is rewritten. In the input's format
and without writer options the output is the input's bytes (a file copied, a callable target
given those bytes): :data:`COPIED`; otherwise (another format, writer options, no input bytes
at hand) a straight conversion: :data:`CONVERTED`. The result's ``unchanged`` member (and so
every report) says which.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from service.io.errors import FormatError
from service.workflows.provenance import stamp_bytes, stamp_file
from service.workflows.unchanged import (
    CONVERTED,
    COPIED,
    WORDS,
    Original,
    marked,
    original_bytes,
    returned_unchanged,
)

if TYPE_CHECKING:
    from service.core.geometry import Geometry
    from service.core.params import SmoothingParams
    from service.core.progress import ProgressCallback
    from service.core.result import SmoothResult
    from service.io import GeometryDocument

__all__ = [
    "CONVERTED",
    "COPIED",
    "Engine",
    "OutputFormatError",
    "Smoothed",
    "Store",
    "counted",
    "encode",
    "returned_unchanged",
    "run_engine",
    "smooth_document",
    "smooth_file",
    "smooth_streamed",
    "streamed_format_of",
    "write_document",
]

#: How a caller runs the engine on the geometry it read (default: :func:`run_engine`).
Engine = Callable[["Geometry"], "SmoothResult"]
#: A target that is not a file path: takes the result and the encoded output.
Store = Callable[["SmoothResult", bytes], None]


class OutputFormatError(FormatError):
    """The output format cannot hold the smoothed geometry (raised while encoding it).

    A :class:`~service.io.errors.FormatError` with the same message, format and line, so the
    HTTP and job answers are the format error's; ``target_fmt`` is the format being written
    (the CLI says ``cannot write <target_fmt>: <message>``, exit status 6).
    """

    def __init__(
        self,
        message: str,
        *,
        fmt: str | None = None,
        line: int | None = None,
        target_fmt: str | None = None,
    ) -> None:
        super().__init__(message, fmt=fmt, line=line)
        self.target_fmt = target_fmt

    @classmethod
    def of(cls, exc: FormatError, target_fmt: str) -> OutputFormatError:
        """``exc`` raised while writing ``target_fmt``."""
        return cls(exc.message, fmt=exc.fmt, line=exc.line, target_fmt=target_fmt)


@dataclass(frozen=True)
class Smoothed:
    """What one run of the use case did.

    Attributes
    ----------
    result : SmoothResult
        The engine's result (points, ``report()``).
    document : GeometryDocument or None
        The input as read (``None``: streamed, never held in memory).
    input_format, output_format : str
        Formats read and written.
    streamed : bool
        Whether the streamed path ran.
    unchanged : str or None
        Nothing smoothed: :data:`COPIED` (the output is the input's bytes) or
        :data:`CONVERTED` (a straight conversion); ``None`` when smoothed.
    """

    result: SmoothResult
    document: GeometryDocument | None
    input_format: str
    output_format: str
    streamed: bool = False
    unchanged: str | None = None

    @property
    def summary(self) -> str | None:
        """``"returned unchanged: input bytes copied"``, ``"converted unchanged"`` or ``None``."""
        return WORDS.get(self.unchanged or "")


def run_engine(
    geometry: Geometry,
    params: SmoothingParams,
    progress: ProgressCallback | None = None,
    *,
    memory_limit: int | None = None,
    run_map: Any = None,
) -> SmoothResult:
    """The one call into the engine (:func:`service.core.smooth`, untiled or tiled)."""
    from service import core

    if memory_limit is None and run_map is None:
        return core.smooth(geometry, params, progress=progress)
    return core.smooth(geometry, params, progress, memory_limit=memory_limit, run_map=run_map)


def counted(result: SmoothResult, doc: GeometryDocument) -> SmoothResult:
    """``result`` with the counts of the file ``doc`` was read from (issue 38): vertices in,
    points solved after welding, vertices written (less the outliers ``drop`` leaves out) and
    the vertices welded onto another."""
    import dataclasses

    from service.core.result import PointCounts
    from service.io._shared.flags import dropped_rows

    n_in, solved = doc.n_output, result.n_points
    counts = PointCounts(n_in, solved, n_in - dropped_rows(doc, result), n_in - doc.geometry.n)
    return dataclasses.replace(result, counts=counts)


def encode(doc: GeometryDocument, fmt: str, points: Any = None, **options: Any) -> bytes:
    """``doc`` with ``points`` as a ``fmt`` file (:func:`service.io.write_geometry` options).

    Raises
    ------
    OutputFormatError
        ``fmt`` cannot hold these points (a coordinate a LAS scale cannot hold, ...).
    OutputRefused, UnsupportedFormat
        As :func:`service.io.write_geometry` raises them.
    ParameterError
        A ``crs`` this input or format cannot take (field ``crs``: HTTP 422, CLI status 4).
    """
    from service.io import write_geometry

    try:
        return write_geometry(doc, fmt, points, **options)
    except FormatError as exc:
        if type(exc) is not FormatError:  # refused or unsupported formats keep their class
            raise
        raise OutputFormatError.of(exc, fmt) from exc
    except ValueError as exc:
        if options.get("crs") is None or isinstance(exc, FormatError):
            raise
        from service.core.errors import ParameterError

        raise ParameterError(str(exc), field="crs") from exc


def write_document(
    doc: GeometryDocument, target: str | Path, fmt: str, points: Any = None, **options: Any
) -> None:
    """:func:`encode` ``doc`` and write it to the file ``target`` atomically."""
    from service.io.atomic import write_file

    write_file(target, encode(doc, fmt, points, **options))


def streamed_format_of(
    source: Path | GeometryDocument,
    target: Path | Store,
    params: SmoothingParams,
    *,
    fmt: str | None = None,
    out_fmt: str | None = None,
    weld: bool | None = None,
    xyz_dims: int | None = None,
    options: Mapping[str, Any] | None = None,
) -> str | None:
    """The format to stream ``source`` in, or ``None`` for the in-memory path: a tiled run
    (``tile_points``) from a file to a file, no writer options, and a file
    :func:`service.io.stream.streamed_format` accepts (same format out, no welding, three
    coordinates)."""
    if not params.tile_points or not isinstance(source, Path) or not isinstance(target, Path):
        return None
    if options and any(options.values()):
        return None
    from service.io.stream import streamed_format

    return streamed_format(source, fmt, out_fmt, weld, xyz_dims)


def smooth_streamed(
    src: Path,
    dst: Path,
    fmt: str,
    params: SmoothingParams,
    progress: ProgressCallback | None = None,
    *,
    memory_limit: int | None = None,
    run_map: Any = None,
) -> Smoothed:
    """Read the coordinates of ``src`` in chunks, smooth them, write ``dst`` atomically by
    streaming ``src`` again with the new coordinates."""
    from service.core.geometry import Geometry
    from service.io.atomic import atomic_path
    from service.io.stream import read_coordinates, rewrite

    P, faces = read_coordinates(src, fmt)
    result = run_engine(Geometry(P, faces=faces), params, progress, memory_limit=memory_limit,
                        run_map=run_map)  # fmt: skip
    same = returned_unchanged(result, P)
    del P
    with atomic_path(dst) as tmp:
        if same:  # nothing smoothed: the input's bytes, not a rewrite
            import shutil

            shutil.copyfile(src, tmp)
        else:
            rewrite(src, tmp, fmt, result.points)
            stamp_file(tmp, fmt)
    if same:
        return Smoothed(marked(result, COPIED), None, fmt, fmt, streamed=True, unchanged=COPIED)
    return Smoothed(result, None, fmt, fmt, streamed=True)


def smooth_document(
    doc: GeometryDocument,
    params: SmoothingParams,
    out_fmt: str | None = None,
    *,
    geometry: Geometry | None = None,
    engine: Engine | None = None,
    check: Callable[[Geometry], None] | None = None,
    progress: ProgressCallback | None = None,
) -> Smoothed:
    """Smooth a document read in memory: the output format checked first (it must hold this
    input), then ``check`` (a caller's own refusal), then the engine on ``geometry`` (default
    ``doc.geometry``)."""
    from service.io.dispatch import check_output

    fmt = out_fmt or doc.source_format
    check_output(doc, fmt)  # a format that cannot hold this input: refused before smoothing
    shape = doc.geometry if geometry is None else geometry
    if check is not None:
        check(shape)
    run = engine or (lambda g: run_engine(g, params, progress))
    return Smoothed(counted(run(shape), doc), doc, doc.source_format, fmt)


def smooth_file(
    source: Path | GeometryDocument,
    target: Path | Store,
    params: SmoothingParams,
    *,
    fmt: str | None = None,
    out_fmt: str | None = None,
    read_options: Mapping[str, Any] | None = None,
    write_options: Mapping[str, Any] | None = None,
    geometry: Geometry | None = None,
    progress: ProgressCallback | None = None,
    engine: Engine | None = None,
    run_map: Any = None,
    check: Callable[[Geometry], None] | None = None,
    stage: Callable[[str], None] | None = None,
    original: Original | None = None,
) -> Smoothed:
    """Read ``source``, smooth it, write ``target``: streamed when it can be (tiles, a file to
    a file in the same format), else in memory. When nothing is smoothed the output is the
    input's bytes (same format, no writer options) or a straight conversion (module docstring).

    Parameters
    ----------
    source : Path or GeometryDocument
        An input file (read as ``fmt``, else by its name or content) or a document read already.
    target : Path or Store
        A file written atomically, or a callable taking the result and the output's bytes.
    params : SmoothingParams
        Smoothing parameters.
    fmt, out_fmt : str, optional
        Input and output formats (output default: the input's).
    read_options, write_options : mapping, optional
        Of :func:`service.io.read_geometry` (``weld``, ``xyz_dims``) and
        :func:`service.io.write_geometry` (``ply_ascii``, ``normals``, ``precision``).
    geometry : Geometry, optional
        What to smooth of a document given as ``source`` (default: its geometry; e.g. with
        extra fixed points).
    progress : callable, optional
        The engine's progress callback.
    engine : callable, optional
        Runs the engine on the geometry read (a caller's progress and tiles); default
        :func:`run_engine` with ``progress`` and ``run_map``.
    run_map : optional
        The tile map of a tiled run (default: tiles in this process).
    check : callable, optional
        A refusal of the geometry read, before the engine runs.
    stage : callable, optional
        Told ``"reading"`` and ``"writing"`` as those stages start.
    original : bytes or Path, optional
        The input's bytes (or its file) when ``source`` is a document read already: copied as
        the output when nothing is smoothed (default: ``source`` itself when it is a file; else
        an unchanged output is converted).
    """
    reading, writing = dict(read_options or {}), dict(write_options or {})
    tell = stage or (lambda name: None)
    streamed = streamed_format_of(source, target, params, fmt=fmt, out_fmt=out_fmt,
                                  weld=reading.get("weld"), xyz_dims=reading.get("xyz_dims"),
                                  options=writing)  # fmt: skip
    if streamed:
        assert isinstance(source, Path) and isinstance(target, Path)
        return smooth_streamed(source, target, streamed, params, progress, run_map=run_map)
    if not isinstance(source, Path):
        doc = source
    else:
        original = source if original is None else original
        from service.io import read_geometry

        tell("reading")
        doc = read_geometry(source, fmt, **reading)
    if writing.get("crs") is not None:  # a crs this output cannot take: refused before smoothing
        encode(doc, out_fmt or doc.source_format, None, **writing)
    if engine is None and run_map is not None:
        engine = lambda g: run_engine(g, params, progress, run_map=run_map)  # noqa: E731
    done = smooth_document(doc, params, out_fmt, geometry=geometry, engine=engine, check=check,
                           progress=progress)  # fmt: skip
    tell("writing")
    return _write(done, target, geometry or doc.geometry, original, writing)


def _write(
    done: Smoothed,
    target: Path | Store,
    smoothed: Geometry,
    original: Original | None,
    writing: Mapping[str, Any],
) -> Smoothed:
    """Write the in-memory path's output: the input's bytes when nothing was smoothed and they
    can stand for the output (same format, no writer options), else the encoded document."""
    import dataclasses

    from service.io._shared.flags import with_outliers

    assert done.document is not None
    doc, points = with_outliers(done.document, done.result.points, done.result,
                                done.output_format)  # fmt: skip
    data = None
    if returned_unchanged(done.result, smoothed.points) and doc is done.document:
        if done.output_format == doc.source_format and not any(writing.values()):
            data = original_bytes(original)
        how = CONVERTED if data is None else COPIED
        done = dataclasses.replace(done, result=marked(done.result, how), unchanged=how)
    if data is None:
        data = stamp_bytes(encode(doc, done.output_format, points, **writing), done.output_format)
    if isinstance(target, Path):
        from service.io.atomic import write_file

        write_file(target, data)
    else:
        target(done.result, data)
    return done
