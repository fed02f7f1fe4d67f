"""``geosmooth smooth INPUT -o OUTPUT``: the use case read -> smooth -> write
(:func:`service.workflows.smooth_file.smooth_file`) with the command line's options.

Everything that can be checked without reading the input is checked first (parameters,
formats, the ``--fixed`` file, whether the output can be written), so a mistake costs nothing.
Typed errors of the engine and the readers propagate to :func:`service.cli.main`, which prints
them with their class's exit status.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import re
import sys
import time
from collections.abc import Iterator, Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from service.cli.errors import CliError, os_reason
from service.cli.output import (
    check_crs,
    check_format,
    check_writable,
    given_writer_options,
    output_format,
    refuse_own_input,
    write_json_report,
    write_output,
)
from service.cli.params import PIPELINE_OPTIONS, params_from_args
from service.cli.parser_base import version
from service.cli.progress import ProgressDisplay, show_summary
from service.core.params import SmoothingParams
from service.exit_codes import EXIT_INPUT, EXIT_OK, EXIT_OUTPUT, EXIT_USAGE

if TYPE_CHECKING:
    from service.core.errors import TauOutOfRange
    from service.core.geometry import Geometry
    from service.io import GeometryDocument
    from service.workflows.smooth_file import Smoothed, Store

__all__ = ["read_fixed_indices", "read_limits", "run", "smooth_one", "write_options"]


def read_fixed_indices(path: str | os.PathLike[str]) -> list[int]:
    """Read the point indices of a ``--fixed`` file.

    Indices are 0-based integers separated by whitespace, commas, semicolons or newlines;
    ``#`` starts a comment that runs to the end of the line.

    Raises
    ------
    CliError
        Exit status 3 when the file cannot be read or holds something other than integers.
    """
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise CliError(f"--fixed: cannot read {path}: {os_reason(exc)}", EXIT_INPUT) from exc
    out: list[int] = []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        for token in re.split(r"[\s,;]+", raw.split("#", 1)[0]):
            if not token:
                continue
            try:
                out.append(int(token))
            except ValueError:
                raise CliError(
                    f"--fixed: {path}, line {lineno}: {token!r} is not an integer point index",
                    EXIT_INPUT,
                ) from None
    return out


def read_input(
    source: str, fmt: str | None, weld: bool | None, xyz_dims: int | None
) -> GeometryDocument:
    """Read INPUT (``-``: stdin); the format from ``fmt``, the name, or the content."""
    from service.io import detect_format, read_geometry, sniff_format

    name = None if source == "-" else Path(source).name
    kind = fmt or (detect_format(name) if name and Path(name).suffix else None)
    if xyz_dims is not None and kind not in (None, "xyz"):  # before reading anything
        raise CliError(f"--xyz-dims applies to XYZ input only, not {kind}", EXIT_USAGE)
    try:
        data = sys.stdin.buffer.read() if source == "-" else Path(source).read_bytes()
    except OSError as exc:
        raise CliError(f"cannot read {source}: {os_reason(exc)}", EXIT_INPUT) from exc
    kind = kind or sniff_format(data)
    if xyz_dims is not None and kind not in (None, "xyz"):
        raise CliError(f"--xyz-dims applies to XYZ input only, not {kind}", EXIT_USAGE)
    return read_geometry(data, kind, filename=name, weld=weld, xyz_dims=xyz_dims)


def _with_fixed(doc: GeometryDocument, indices: Sequence[int] | None) -> Geometry:
    """The document's geometry plus the ``--fixed`` points (file indices when welded)."""
    import numpy as np

    from service.core.errors import GeosmoothError, IndexOutOfRange

    geometry = doc.geometry
    if indices is None:
        return geometry
    try:
        extra = list(indices)
        if doc.weld is not None:  # the file's vertex i is the geometry's doc.weld.index[i]
            n_file = int(doc.weld.index.size)
            bad = [i for i in indices if not 0 <= i < n_file]
            if bad:
                raise IndexOutOfRange(
                    f"fixed index {bad[0]} is outside [0, {n_file})",
                    field="geometry.fixed",
                    indices=bad,
                )
            extra = [int(doc.weld.index[i]) for i in indices]
        previous = [] if geometry.fixed is None else geometry.fixed.tolist()
        return replace(geometry, fixed=np.asarray(previous + extra, dtype=np.int64))
    except GeosmoothError as exc:
        raise CliError.located(exc, "--fixed") from exc


def tau_message(exc: TauOutOfRange, params: SmoothingParams) -> str:
    """TauOutOfRange as one line that states the valid range of the option the user gave."""
    tau_max = float(exc.tau_max)
    if tau_max <= 0.0:
        return str(exc.message)
    if params.rms is not None and exc.tau > 0:
        from service.core.search.budget import rms_range

        rms_max = rms_range(params.rms, float(exc.tau), tau_max)
        return (
            f"--rms {params.rms:g} is out of range for this input: the valid range is "
            f"(0, {rms_max:.6g}) (it gives tau = {float(exc.tau):.6g}, and tau must lie in "
            f"(0, phi(0) = {tau_max:.6g}))"
        )
    return (
        f"--tau {float(exc.tau):g} is out of range for this input: the valid range is "
        f"(0, {tau_max:.6g}), the upper bound phi(0) being the deviation of the fully smoothed "
        "shape (each connected part collapsed onto its weighted centroid, or, with fixed "
        "points or pinned curve ends, the smoothest shape through them)"
    )


def _details(doc: GeometryDocument) -> list[str]:
    """Facts about the input for the summary (``"16301 faces"``, ...)."""
    g = doc.geometry
    out = []
    if g.faces is not None:
        out.append(f"{len(g.faces)} faces")
    if g.edges is not None:
        out.append(f"{len(g.edges)} edges")
    if doc.polylines:
        out.append(f"{len(doc.polylines)} polylines")
    if doc.weld is not None:
        out.append(f"welded from {doc.weld.n_original} vertices")
    return out


def _assign_crs(ns: argparse.Namespace, doc: GeometryDocument | None) -> None:
    """``--in-crs``: the CRS of a LAS/LAZ input (PDAL's ``a_srs``); exit status 2 for a value
    pyproj does not know or another format (checked first with ``doc`` ``None``)."""
    text = getattr(ns, "in_crs", None)
    if not text:
        return
    import pyproj

    code = str(text).strip().upper().removeprefix("EPSG:")
    try:
        crs = pyproj.CRS.from_user_input(f"EPSG:{int(code)}" if code.isdigit() else text)
    except pyproj.exceptions.CRSError:
        raise CliError(f"--in-crs: {text!r} is not a CRS pyproj knows", EXIT_USAGE) from None
    if doc is None:
        return
    header = getattr(doc.layout, "header", None)
    if header is None or not hasattr(header, "add_crs"):
        raise CliError(f"--in-crs applies to LAS/LAZ input, not {doc.source_format}", EXIT_USAGE)
    from service.io.formats.las_meta import assign_crs

    assign_crs(header, crs)


def _selects(ns: argparse.Namespace) -> bool:
    return bool(getattr(ns, "where", None) or getattr(ns, "fix_classes", None))


def _selection(ns: argparse.Namespace, doc: GeometryDocument | None) -> list[int] | None:
    """The file indices ``--where`` / ``--fix-classes`` hold fixed (``None``: no selection);
    with ``doc`` ``None`` only the expressions are checked. Exit status 2 for a bad one."""
    if not _selects(ns):
        return None
    from service.workflows.selection import SelectionError, class_list, fixed_outside, parse_where

    try:
        classes = class_list(ns.fix_classes) if getattr(ns, "fix_classes", None) else None
        if doc is None:
            if ns.where:
                parse_where(ns.where)
            return None
        g = doc.geometry
        pts = g.points if doc.weld is None else g.points[doc.weld.index]  # the file's numbering
        out = fixed_outside(pts, doc.attributes, ns.where, classes)
    except SelectionError as exc:
        raise CliError(exc.message, EXIT_USAGE) from exc
    ns.selection_counts = (len(pts) - len(out), len(pts))
    return [int(i) for i in out]


def _check_options(ns: argparse.Namespace) -> tuple[SmoothingParams, str | None]:
    """Everything that needs no input file: parameters, formats, outputs."""
    params = params_from_args(ns)
    check_format(ns.input_format, "--input-format")
    if ns.xyz_dims is not None and ns.xyz_dims < 1:
        raise CliError(f"--xyz-dims: must be at least 1, got {ns.xyz_dims}", EXIT_USAGE)
    _selection(ns, None)  # a bad expression before anything is read
    _assign_crs(ns, None)
    out_fmt = output_format(ns.output, ns.format)
    refuse_own_input(ns.input, ns.output, getattr(ns, "overwrite", False))
    check_writable(ns.output, "output")
    if ns.report:
        check_writable(ns.report, "report")
    return params, out_fmt


def _streamed(
    ns: argparse.Namespace, params: SmoothingParams, out_fmt: str | None, options: dict[str, Any]
) -> str | None:
    """The format of a tiled run read and written in chunks (issue 23), else ``None``: a file
    to a file, no ``--fixed``, no writer option
    (:func:`service.workflows.smooth_file.streamed_format_of`)."""
    if ns.fixed or _selects(ns) or getattr(ns, "in_crs", None) or "-" in (ns.input, ns.output):
        return None
    from service.workflows.smooth_file import streamed_format_of

    return streamed_format_of(Path(ns.input), Path(ns.output), params, fmt=ns.input_format,
                              out_fmt=out_fmt, weld=ns.weld, xyz_dims=ns.xyz_dims,
                              options=options)  # fmt: skip


@contextlib.contextmanager
def _cli_errors(params: SmoothingParams, progress: ProgressDisplay) -> Iterator[None]:
    """The use case's failures as the CLI states them (both paths, one place)."""
    from service.core.errors import TauOutOfRange
    from service.workflows.smooth_file import OutputFormatError

    try:
        yield
    except TauOutOfRange as exc:
        raise CliError(tau_message(exc, params), exc.exit_code) from exc
    except OutputFormatError as exc:  # the format cannot hold this geometry: an output problem
        raise CliError(f"cannot write {exc.target_fmt}: {exc.message}", EXIT_OUTPUT) from exc
    finally:
        progress.close()


def _tile_map(streamed: str | None) -> contextlib.AbstractContextManager[Any]:
    """Local tile processes of a streamed run (``GEOSMOOTH_TILE_WORKERS``, default 1: none)."""
    workers = max(1, int(os.environ.get("GEOSMOOTH_TILE_WORKERS", "1") or 1))
    if not streamed or workers <= 1:
        return contextlib.nullcontext()
    from service.jobs.tiles.local import local_tiles

    return local_tiles(workers)


def read_limits(ns: argparse.Namespace) -> contextlib.AbstractContextManager[Any]:
    """``--max-points`` / ``--max-memory`` in force for the reads of this command (every path:
    :mod:`service.io.limits`)."""
    from service.io.limits import ReadLimits, limits_of, reading

    given: dict[str, Any] = {}
    for option in ("max_points", "max_memory"):
        try:
            given[option] = getattr(limits_of(**{option: getattr(ns, option, None)}), option)
        except ValueError as exc:
            raise CliError(f"--{option.replace('_', '-')}: {exc}", EXIT_USAGE) from exc
    return reading(ReadLimits(**given))


def write_options(ns: argparse.Namespace) -> dict[str, Any]:
    """The writer options of the command line (:func:`service.io.write_geometry`)."""
    options = {**given_writer_options(ns), "ply_ascii": ns.ascii}
    if getattr(ns, "crs", None):
        options["crs"] = check_crs(ns.crs)
    return options


def _check_crs_applies(doc: GeometryDocument, out_fmt: str | None, options: dict[str, Any]) -> None:
    """``--crs`` for input that is not geographic, or a GPX/GeoJSON output: exit status 2
    before smoothing (the writer's own check, on the input's points)."""
    if not options.get("crs"):
        return
    from service.workflows.smooth_file import encode

    try:
        encode(doc, out_fmt or doc.source_format, None, **options)
    except ValueError as exc:
        raise CliError(f"--crs: {exc}", EXIT_USAGE) from exc


def run(ns: argparse.Namespace, err: TextIO) -> int:
    """Run ``geosmooth smooth INPUT -o OUTPUT`` (one file: :func:`service.cli.batch.run` decides);
    returns the exit status (errors are raised)."""
    from service.cli.progress.stages import display_for
    from service.core.params import TOLERANCE

    started = time.perf_counter()
    try:  # the option's raw text (its validation comes with the parameters', below)
        tolerance = float(getattr(ns, "tolerance", None) or TOLERANCE)
    except ValueError:
        tolerance = TOLERANCE
    progress = display_for(ns, err, tolerance)
    try:
        params, done = smooth_one(ns, progress)
        _report(ns, params, done, started, progress)
    finally:
        progress.close()
    return ns.exit_unchanged if done.unchanged else EXIT_OK


def smooth_one(
    ns: argparse.Namespace, progress: ProgressDisplay
) -> tuple[SmoothingParams, Smoothed]:
    """Smooth the one file ``ns.input`` into ``ns.output`` (errors are raised)."""
    from service.workflows.cpu_limit import cpu_time_limit, parse_time_limit

    try:
        seconds = parse_time_limit(getattr(ns, "time_limit", None))
    except ValueError as exc:
        raise CliError(f"--time-limit: {exc}", EXIT_USAGE) from exc
    with read_limits(ns), cpu_time_limit(seconds):
        return _smooth_one(ns, progress)


def _smooth_one(
    ns: argparse.Namespace, progress: ProgressDisplay
) -> tuple[SmoothingParams, Smoothed]:
    from service.workflows.smooth_file import smooth_file

    params, out_fmt = _check_options(ns)
    options = write_options(ns)
    streamed = _streamed(ns, params, out_fmt, options)
    source: Path | GeometryDocument = Path(ns.input)
    target: Path | Store = Path(ns.output)
    geometry = doc = None
    if not streamed:
        fixed = read_fixed_indices(ns.fixed) if ns.fixed else None
        progress.stage("reading")
        source = doc = read_input(ns.input, ns.input_format, ns.weld, ns.xyz_dims)
        _assign_crs(ns, doc)
        outside = _selection(ns, doc)
        if outside is not None:
            fixed = (fixed or []) + outside
        geometry = _with_fixed(doc, fixed)
        progress.expect(_model_seconds(geometry, params))
        progress.sized(geometry.n)
        target = lambda _result, data: write_output(ns.output, data, "output")  # noqa: E731
    with _cli_errors(params, progress), _tile_map(streamed) as run_map:
        if doc is not None:
            _check_crs_applies(doc, out_fmt, options)
        done = smooth_file(source, target, params, fmt=streamed, out_fmt=out_fmt,
                           read_options={"weld": ns.weld, "xyz_dims": ns.xyz_dims},
                           write_options=options, geometry=geometry, progress=progress,
                           run_map=run_map, stage=progress.stage,
                           original=None if ns.input == "-" else Path(ns.input))  # fmt: skip
    return params, done


def _model_seconds(geometry: Geometry, params: SmoothingParams) -> float:
    """The engine's model of the time smoothing ``geometry`` takes (for the progress estimate)."""
    from service.core.linalg.resources import estimate_resources

    faces = None if geometry.faces is None else len(geometry.faces)
    return estimate_resources(geometry.n, geometry.dim, geometry.kind, params, faces).seconds


def _report(
    ns: argparse.Namespace,
    params: SmoothingParams,
    done: Smoothed,
    started: float,
    progress: ProgressDisplay,
) -> None:
    """The JSON report (``--report``) and the summary on stderr."""
    from service.io.dispatch import output_notes

    report: dict[str, Any] = dict(done.result.report())
    if ns.report:
        report.update(
            input=ns.input,
            input_format=done.input_format,
            output=ns.output,
            output_format=done.output_format,
            params=params.model_dump(mode="json"),
            **{k: getattr(ns, k) for k in PIPELINE_OPTIONS if getattr(ns, k, None) is not None},
            geosmooth_version=version(),
            wall_seconds=time.perf_counter() - started,
        )
        if done.streamed:
            report["streamed"] = True
        write_json_report(ns.report, report)
    doc = done.document
    details = ["streamed"] if doc is None else _details(doc)
    if getattr(ns, "selection_counts", None):
        chosen, total = ns.selection_counts
        details.append(f"{chosen} of {total} points selected, {total - chosen} held fixed")
    notes = [] if doc is None else output_notes(doc, done.output_format, ns.crs)
    show_summary(progress, report, ns, params, started, details=details, notes=notes)
