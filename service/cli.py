"""The ``geosmooth`` command line: ``smooth`` a file, ``serve`` the HTTP API, ``submit`` to it.

``geosmooth smooth INPUT -o OUTPUT --tau T`` reads a mesh, polyline network or point cloud
(``service.io``), smooths it with :func:`service.core.pipeline` and writes the result in the same
vertex order. Parameters are validated once, by :class:`service.core.SmoothingParams`; the
CLI only maps option names to field names (:func:`params_from_args`) and pydantic's messages to
one-line errors. Every failure is one line on stderr and a documented exit code
(:data:`EXIT_CODES`); ``GEOSMOOTH_DEBUG=1`` adds the traceback.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import re
import sys
import tempfile
import textwrap
import time
import traceback
import typing
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any, NoReturn, TextIO

from pydantic import ValidationError

from service.core.params import SmoothingParams

__all__ = [
    "EXIT_CODES",
    "SUBMIT_EXIT_CODES",
    "CliError",
    "build_parser",
    "main",
    "params_from_args",
    "read_fixed_indices",
]

from service.exit_codes import (
    EXIT_CODES,
    EXIT_GEOMETRY,
    EXIT_INPUT,
    EXIT_INTERNAL,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_OUTPUT,
    EXIT_SOLVER,
    EXIT_USAGE,
    SUBMIT_EXIT_CODES,
)

#: The three ways to pick lambda (a required, mutually exclusive group). Every other
#: :class:`SmoothingParams` field becomes an option too, in the model's order, named ``--`` +
#: the field name with ``_`` -> ``-`` (so a field added to the model appears here by itself).
_TARGET_FIELDS = ("tau", "rms", "lam")
_METAVARS = {
    "tau": "T",
    "rms": "R",
    "lam": "L",
    "k": "K",
    "sigma_f": "SIGMA",
    "sigma_h": "SIGMA",
    "tolerance": "XI",
    "max_iterations": "N",
}
_HELP_PREFIX = {
    "tau": "Smoothing factor: target for phi = sum_i w_i^2 ||x_i - p_i||^2.",
    "rms": "Target RMS displacement (tau = sum_i w_i^2 * R^2).",
    "lam": "Use this lambda directly (no tau search).",
}


class CliError(Exception):
    """A failure the CLI reports as one line and an exit status.

    Parameters
    ----------
    message : str
        The line after ``geosmooth: error: ``.
    code : int
        Exit status, one of :data:`EXIT_CODES`.
    """

    def __init__(self, message: str, code: int) -> None:
        super().__init__(message)
        self.message = message
        self.code = code


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors are one line (no usage block) and do not exit."""

    def error(self, message: str) -> NoReturn:
        raise CliError(f"{message} (see '{self.prog} --help')", EXIT_USAGE)


def _option(field: str) -> str:
    return "--" + field.replace("_", "-")


def _debug() -> bool:
    return os.environ.get("GEOSMOOTH_DEBUG", "").strip() not in ("", "0", "false", "no")


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("geosmooth")
    except PackageNotFoundError:  # running from a source tree that is not installed
        return "unknown"


# --------------------------------------------------------------------------- parameters


def _field_help(name: str) -> str:
    info = SmoothingParams.model_fields[name]
    text = _HELP_PREFIX.get(name) or (info.description or "")
    text = text.replace("%", "%%")
    if name not in _TARGET_FIELDS:
        default = info.default
        shown = "off" if default is False else default
        text += f" [default: {shown}]"
    return text


def _add_smoothing_options(parser: argparse.ArgumentParser) -> None:
    """Add one option per :class:`SmoothingParams` field (defaults stay in the model)."""
    target = parser.add_argument_group(
        "smoothing target (exactly one)",
        _wrap(
            "tau is the budget for the weighted sum of squared displacements (report eq. 3 and "
            "15); it must lie in (0, phi(0)), phi(0) being the deviation from the weighted "
            "centroid (of each connected part)."
        ),
    )
    group = target.add_mutually_exclusive_group(required=True)
    for name in _TARGET_FIELDS:
        group.add_argument(
            _option(name), dest=name, metavar=_METAVARS[name], default=None, help=_field_help(name)
        )
    opts = parser.add_argument_group("smoothing options")
    for name in SmoothingParams.model_fields:
        if name in _TARGET_FIELDS:
            continue
        info = SmoothingParams.model_fields[name]
        flags = [_option(name)] + (["-k"] if name == "k" else [])
        if info.annotation is bool:
            opts.add_argument(
                *flags, dest=name, action="store_true", default=None, help=_field_help(name)
            )
            continue
        args = typing.get_args(info.annotation)
        literal = bool(args) and all(isinstance(a, str) for a in args)  # a Literal of names
        metavar = "{" + ",".join(args) + "}" if literal else _METAVARS.get(name, name.upper())
        # Values stay strings: SmoothingParams parses and validates them (one validation).
        opts.add_argument(*flags, dest=name, metavar=metavar, default=None, help=_field_help(name))


def params_from_args(ns: argparse.Namespace) -> SmoothingParams:
    """Build the :class:`SmoothingParams` of a parsed ``smooth`` or ``submit`` command line.

    Only options the user gave are passed, so every default comes from the model.

    Parameters
    ----------
    ns : argparse.Namespace
        Result of :meth:`argparse.ArgumentParser.parse_args`; attributes named like the fields.

    Returns
    -------
    SmoothingParams

    Raises
    ------
    CliError
        Exit status 2, with pydantic's first complaint as one line naming the option, e.g.
        ``--tau: must be greater than 0``.
    """
    given = {
        name: getattr(ns, name)
        for name in SmoothingParams.model_fields
        if getattr(ns, name, None) is not None
    }
    try:
        return SmoothingParams.model_validate(given)
    except ValidationError as exc:
        raise CliError(_validation_message(exc), EXIT_USAGE) from exc


def _validation_message(exc: ValidationError) -> str:
    """Pydantic's errors as one line: ``--option: must be ...`` joined by ``; ``."""
    parts = []
    for err in exc.errors(include_url=False):
        msg = str(err.get("msg", "invalid value"))
        msg = re.sub(r"^Value error, ", "", msg)
        msg = re.sub(r"^Input should be ", "must be ", msg)
        msg = re.sub(r"^Extra inputs are not permitted", "unknown parameter", msg)
        loc = [str(part) for part in err.get("loc", ()) if part != "__root__"]
        if loc:
            parts.append(f"{_option(loc[0])}: {msg}")
        else:
            for name in _TARGET_FIELDS:
                msg = re.sub(rf"\b{name}\b", _option(name), msg)
            parts.append(msg)
    return "; ".join(parts) or "invalid parameters"


def read_fixed_indices(path: str | os.PathLike[str]) -> list[int]:
    """Read the point indices of a ``--fixed`` file.

    Indices are 0-based integers separated by whitespace, commas, semicolons or newlines;
    ``#`` starts a comment that runs to the end of the line.

    Parameters
    ----------
    path : path-like
        The text file.

    Returns
    -------
    list of int
        In file order (duplicates are harmless).

    Raises
    ------
    CliError
        Exit status 3 when the file cannot be read or holds something other than integers.
    """
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise CliError(f"--fixed: cannot read {path}: {_os_reason(exc)}", EXIT_INPUT) from exc
    out: list[int] = []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        for token in re.split(r"[\s,;]+", raw.split("#", 1)[0]):
            if not token:
                continue
            try:
                value = int(token)
            except ValueError:
                raise CliError(
                    f"--fixed: {path}, line {lineno}: {token!r} is not an integer point index",
                    EXIT_INPUT,
                ) from None
            out.append(value)
    return out


# --------------------------------------------------------------------------- parser


def _wrap(text: str) -> str:
    return textwrap.fill(text, 78)


def _epilog(submit: bool = True) -> str:
    table = dict(EXIT_CODES)
    if submit:
        table.update(SUBMIT_EXIT_CODES)
    codes = "\n".join(
        textwrap.fill(text, 78, initial_indent=f"  {code:>3}  ", subsequent_indent=" " * 7)
        for code, text in sorted(table.items())
    )
    return (
        "examples:\n"
        "  geosmooth smooth bunny.ply -o bunny-smooth.ply --tau 2e-4 --report report.json\n"
        "  geosmooth smooth track.obj -o track-smooth.obj --rms 3 --fix-boundary\n"
        "  geosmooth serve --port 8000\n"
        "  geosmooth submit bunny.ply --server http://127.0.0.1:8000 -o out.ply --tau 2e-4\n\n"
        f"exit status:\n{codes}\n\n"
        "Errors are one line on stderr; set GEOSMOOTH_DEBUG=1 for a traceback."
    )


def build_parser() -> argparse.ArgumentParser:
    """The ``geosmooth`` argument parser with its ``smooth``, ``serve`` and ``submit`` commands.

    Returns
    -------
    argparse.ArgumentParser
    """
    from service.io import FORMATS

    fmt_metavar = "{" + ",".join(FORMATS) + "}"
    raw = argparse.RawDescriptionHelpFormatter
    parser = _Parser(
        prog="geosmooth",
        description=_wrap(
            "Smooth triangle meshes, polylines / curve networks and point clouds in any "
            "dimension with a global deviation budget tau (KU Leuven report TW 451)."
        ),
        epilog=_epilog(),
        formatter_class=raw,
    )
    parser.add_argument("--version", action="version", version=f"geosmooth {_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    sm = sub.add_parser(
        "smooth",
        help="smooth a file (PLY, OBJ, XYZ or JSON)",
        description=_wrap(
            "Smooth a mesh, polyline network or point cloud. The output keeps the "
            "input's vertex count, order and connectivity."
        ),
        epilog=_epilog(submit=False),
        formatter_class=raw,
    )
    sm.add_argument(
        "input", metavar="INPUT", help="input file ('-' reads stdin; the format is sniffed)"
    )
    sm.add_argument(
        "-o", "--output", required=True, metavar="OUTPUT", help="output file ('-' writes stdout)"
    )
    _add_smoothing_options(sm)
    files = sm.add_argument_group("files")
    files.add_argument(
        "--fixed",
        metavar="FILE",
        help="text file of 0-based point indices to keep fixed (bit-identical): separated by "
        "whitespace, commas or newlines; '#' starts a comment",
    )
    files.add_argument(
        "--format",
        dest="format",
        metavar=fmt_metavar,
        help="output format when the OUTPUT extension does not say [default: the input's]",
    )
    files.add_argument(
        "--input-format",
        metavar=fmt_metavar,
        help="input format when the INPUT extension does not say",
    )
    files.add_argument(
        "--xyz-dims",
        type=int,
        metavar="D",
        help="XYZ input: the first D columns are coordinates (any dimension) [default: 2 for "
        "two columns, else 3; other columns are ignored]",
    )
    files.add_argument(
        "--ascii", action="store_true", help="write ASCII PLY [default: binary little-endian]"
    )
    files.add_argument(
        "--weld",
        action="store_true",
        help="weld exactly coincident vertices before smoothing (meshes stored with split "
        "normals, e.g. STL exports); the output keeps the input's vertices",
    )
    files.add_argument(
        "--report", metavar="REPORT.json", help="write the run's diagnostics as JSON"
    )
    files.add_argument(
        "-q", "--quiet", action="store_true", help="print nothing on success (errors still go)"
    )

    sv = sub.add_parser(
        "serve",
        help="run the HTTP service",
        description="Run the HTTP service (embedded job queue, no Redis needed).",
        epilog=_epilog(submit=False),
        formatter_class=raw,
    )
    sv.add_argument("--host", default="127.0.0.1", help="interface to bind [default: %(default)s]")
    sv.add_argument("--port", type=int, default=8000, help="TCP port [default: %(default)s]")
    sv.add_argument(
        "--workers", type=int, default=None, help="solver worker processes [default: settings]"
    )
    sv.add_argument("--data-dir", default=None, help="job store directory [default: settings]")

    su = sub.add_parser(
        "submit",
        help="smooth a file on a running geosmooth server",
        description=_wrap(
            "Upload INPUT to a geosmooth server, wait for the job and download the result."
        ),
        epilog=_epilog(),
        formatter_class=raw,
    )
    su.add_argument("input", metavar="INPUT", help="input file")
    su.add_argument("--server", required=True, metavar="URL", help="e.g. http://127.0.0.1:8000")
    su.add_argument("-o", "--output", required=True, metavar="OUTPUT", help="output file")
    _add_smoothing_options(su)
    su.add_argument("--format", dest="format", metavar=fmt_metavar, help="output format")
    su.add_argument(
        "--weld",
        action="store_true",
        help="have the server weld exactly coincident vertices (the output keeps the input's)",
    )
    su.add_argument("--report", metavar="REPORT.json", help="write the job's report as JSON")
    su.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")
    return parser


# --------------------------------------------------------------------------- smooth


def _os_reason(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror
    return str(exc) or type(exc).__name__


def _check_format(fmt: str | None, option: str) -> str | None:
    from service.io import FORMATS

    if fmt is not None and fmt not in FORMATS:
        raise CliError(f"{option}: must be one of {', '.join(FORMATS)}, got {fmt!r}", EXIT_USAGE)
    return fmt


def _output_format(output: str, explicit: str | None) -> str | None:
    """Format to write: the output extension, else ``--format``, else ``None`` (the input's)."""
    from service.io import UnsupportedFormat, detect_format

    by_ext: str | None = None
    if output != "-":
        try:
            by_ext = detect_format(output)
        except UnsupportedFormat:
            by_ext = None
    if by_ext and explicit and by_ext != explicit:
        raise CliError(
            f"--format {explicit} contradicts the output file name {output!r} ({by_ext})",
            EXIT_USAGE,
        )
    if by_ext:
        return by_ext
    if explicit:
        return explicit
    if output != "-" and Path(output).suffix:
        raise CliError(f"cannot tell the output format from {output!r}; give --format", EXIT_USAGE)
    return None


def _json_safe(value: Any) -> Any:
    """Make a report JSON-clean: numpy scalars/arrays to Python, non-finite floats to null."""
    if isinstance(value, Mapping):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json_safe(v) for v in value]
    if hasattr(value, "tolist") and not isinstance(value, str):
        return _json_safe(value.tolist())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _write_bytes(target: str, data: bytes, what: str) -> None:
    """Write ``data`` atomically (temporary file + rename); ``-`` is stdout."""
    if target == "-":
        try:
            sys.stdout.buffer.write(data)
            sys.stdout.buffer.flush()
        except OSError as exc:
            raise CliError(
                f"cannot write {what} to stdout: {_os_reason(exc)}", EXIT_OUTPUT
            ) from exc
        return
    path = Path(target)
    tmp: str | None = None
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent or ".")
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
        tmp = None
    except OSError as exc:
        raise CliError(f"cannot write {what} {target}: {_os_reason(exc)}", EXIT_OUTPUT) from exc
    finally:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)


def _check_writable(target: str, what: str) -> None:
    """Fail early (exit status 6) when ``target``'s directory is missing or read-only."""
    if target == "-":
        return
    path = Path(target)
    parent = path.parent
    if path.is_dir():
        raise CliError(f"cannot write {what} {target}: Is a directory", EXIT_OUTPUT)
    if not parent.is_dir():
        raise CliError(f"cannot write {what} {target}: No such directory {parent}", EXIT_OUTPUT)
    if not os.access(parent, os.W_OK | os.X_OK):
        raise CliError(f"cannot write {what} {target}: Permission denied", EXIT_OUTPUT)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _read_input(source: str, fmt: str | None, weld: bool, xyz_dims: int | None) -> Any:
    """Read INPUT through ``service.io``; file problems become exit status 3."""
    from service.core.errors import GeometryError
    from service.io import FormatError, detect_format, read_geometry

    name = None if source == "-" else Path(source).name  # stdin: the reader sniffs the format
    try:
        kind = fmt or (detect_format(name) if name else None)  # refuse GPX & co. before reading
        if xyz_dims is not None and kind not in (None, "xyz"):
            raise CliError(f"--xyz-dims applies to XYZ input only, not {kind}", EXIT_USAGE)
        try:
            data = sys.stdin.buffer.read() if source == "-" else Path(source).read_bytes()
        except OSError as exc:
            raise CliError(f"cannot read {source}: {_os_reason(exc)}", EXIT_INPUT) from exc
        return read_geometry(data, fmt, filename=name, weld=weld, xyz_dims=xyz_dims)
    except CliError:
        raise
    except GeometryError as exc:
        raise CliError(f"{source}: {exc.message}", EXIT_GEOMETRY) from exc
    except FormatError as exc:
        raise CliError(f"{source}: {exc}", EXIT_INPUT) from exc
    except ValueError as exc:
        if xyz_dims is not None and "xyz_dims" in str(exc):  # stdin sniffed as non-XYZ
            raise CliError("--xyz-dims applies to XYZ input only", EXIT_USAGE) from exc
        raise


def _map_fixed(doc: Any, indices: Sequence[int]) -> list[int]:
    """Map ``--fixed`` indices (vertices of the file) to geometry indices.

    When the reader welded coincident vertices (``--weld``), the file's vertex ``i`` is the
    geometry's vertex ``doc.weld.index[i]``; otherwise the two numberings agree.
    """
    weld = getattr(doc, "weld", None)
    if weld is None:
        return list(indices)
    n_file = int(weld.index.size)
    bad = [i for i in indices if not 0 <= i < n_file]
    if bad:
        from service.core.errors import IndexOutOfRange

        raise IndexOutOfRange(
            f"fixed index {bad[0]} is outside [0, {n_file})", field="geometry.fixed", indices=bad
        )
    return [int(weld.index[i]) for i in indices]


def _run_smooth(ns: argparse.Namespace, err: TextIO) -> int:
    from service.cli_progress import ProgressDisplay, format_summary
    from service.core import smooth
    from service.core.errors import (
        GeometryError,
        GeosmoothError,
        ParameterError,
        SolverError,
        TauOutOfRange,
    )
    from service.io import FormatError, write_geometry

    started = time.perf_counter()
    params = params_from_args(ns)
    _check_format(ns.format, "--format")
    _check_format(ns.input_format, "--input-format")
    fixed = read_fixed_indices(ns.fixed) if ns.fixed else None
    if ns.xyz_dims is not None and ns.xyz_dims < 1:
        raise CliError(f"--xyz-dims: must be at least 1, got {ns.xyz_dims}", EXIT_USAGE)
    out_fmt = _output_format(ns.output, ns.format)  # refuse a bad output name before reading
    _check_writable(ns.output, "output")
    if ns.report:
        _check_writable(ns.report, "report")
    doc = _read_input(ns.input, ns.input_format, ns.weld, ns.xyz_dims)
    out_fmt = out_fmt or doc.source_format
    geometry = doc.geometry
    try:
        if fixed is not None:
            extra = _map_fixed(doc, fixed)
            previous = [] if geometry.fixed is None else geometry.fixed.tolist()
            geometry = replace(geometry, fixed=previous + extra)
    except GeometryError as exc:
        raise CliError(f"--fixed: {exc.message}", EXIT_GEOMETRY) from exc

    show = not ns.quiet
    details = []  # for the summary (printed at the end, so that an error stays one line)
    if geometry.faces is not None:
        details.append(f"{len(geometry.faces)} faces")
    if geometry.edges is not None:
        details.append(f"{len(geometry.edges)} edges")
    if doc.polylines:
        details.append(f"{len(doc.polylines)} polylines")
    if doc.weld is not None:
        details.append(f"welded from {doc.weld.n_original} vertices")
    progress = ProgressDisplay(err, enabled=show)
    try:
        result = smooth(geometry, params, progress=progress)
    except TauOutOfRange as exc:
        raise CliError(_tau_message(exc, params), EXIT_GEOMETRY) from exc
    except SolverError as exc:
        raise CliError(f"solver failed: {exc.message}", EXIT_SOLVER) from exc
    except ParameterError as exc:
        where = exc.field.removeprefix("params.")
        prefix = _option(where) if where in SmoothingParams.model_fields else ns.input
        raise CliError(f"{prefix}: {exc.message}", EXIT_GEOMETRY) from exc
    except (GeometryError, GeosmoothError) as exc:
        raise CliError(f"{ns.input}: {exc.message}", EXIT_GEOMETRY) from exc
    finally:
        progress.finish()

    try:
        data = write_geometry(doc, out_fmt, points=result.points, ply_ascii=ns.ascii)
    except FormatError as exc:
        raise CliError(f"cannot write {out_fmt}: {exc}", EXIT_OUTPUT) from exc
    _write_bytes(ns.output, data, "output")

    report = result.report()
    wall = time.perf_counter() - started
    if ns.report:
        full = dict(report)
        full.update(
            {
                "input": ns.input,
                "input_format": doc.source_format,
                "output": ns.output,
                "output_format": out_fmt,
                "params": params.model_dump(mode="json"),
                "geosmooth_version": _version(),
                "wall_seconds": wall,
            }
        )
        text = json.dumps(_json_safe(full), indent=2, allow_nan=False) + "\n"
        _write_bytes(ns.report, text.encode("utf-8"), "report")
    if show:
        err.write(
            format_summary(
                report,
                source=ns.input,
                target=ns.output,
                wall_seconds=time.perf_counter() - started,
                tolerance=params.tolerance if params.lam is None else None,
                details=details,
                notes=doc.notes,
            )
            + "\n"
        )
        err.flush()
    return EXIT_OK


def _tau_message(exc: Any, params: SmoothingParams) -> str:
    """TauOutOfRange as one line that states the valid range of the option the user gave."""
    tau_max = float(exc.tau_max)
    if tau_max <= 0.0:
        return str(exc.message)
    if params.rms is not None and exc.tau > 0:
        # tau = rms^2 * sum of the free points' w_i^2, so rms scales with sqrt(tau).
        rms_max = params.rms * math.sqrt(tau_max / float(exc.tau))
        return (
            f"--rms {params.rms:g} is out of range for this input: the valid range is "
            f"(0, {rms_max:.6g}) (it gives tau = {float(exc.tau):.6g}, and tau must lie in "
            f"(0, phi(0) = {tau_max:.6g}))"
        )
    return (
        f"--tau {float(exc.tau):g} is out of range for this input: the valid range is "
        f"(0, {tau_max:.6g}), the upper bound phi(0) being the deviation of the fully smoothed "
        "shape (each connected part collapsed onto its weighted centroid)"
    )


# --------------------------------------------------------------------------- serve, submit


def _run_serve(ns: argparse.Namespace, err: TextIO) -> int:
    try:
        from service.api.server import serve
    except ImportError as exc:
        raise CliError(f"the HTTP service is not available: {exc}", EXIT_INTERNAL) from exc
    if not 0 < ns.port < 65536:
        raise CliError(f"--port: must be in 1..65535, got {ns.port}", EXIT_USAGE)
    if ns.workers is not None and ns.workers < 1:
        raise CliError(f"--workers: must be at least 1, got {ns.workers}", EXIT_USAGE)
    serve(ns.host, ns.port, ns.workers, ns.data_dir)
    return EXIT_OK


def _run_submit(ns: argparse.Namespace, err: TextIO) -> int:
    params = params_from_args(ns)
    _check_format(ns.format, "--format")
    try:
        from service.client import submit
    except ImportError as exc:
        raise CliError(f"the HTTP client is not available: {exc}", EXIT_INTERNAL) from exc
    return int(
        submit(
            ns.input,
            ns.server,
            params,
            ns.output,
            report=ns.report,
            fmt=ns.format,
            quiet=ns.quiet,
            weld=ns.weld,
        )
    )


_COMMANDS: dict[str, Callable[[argparse.Namespace, TextIO], int]] = {
    "smooth": _run_smooth,
    "serve": _run_serve,
    "submit": _run_submit,
}


# --------------------------------------------------------------------------- main


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``geosmooth``.

    Parameters
    ----------
    argv : sequence of str, optional
        Arguments without the program name; default ``sys.argv[1:]``.

    Returns
    -------
    int
        Exit status (see :data:`EXIT_CODES`).
    """
    err = sys.stderr
    try:
        try:
            ns = build_parser().parse_args(list(argv) if argv is not None else None)
        except SystemExit as exc:  # --help / --version
            return int(exc.code or 0) if isinstance(exc.code, int | None) else EXIT_USAGE
        return _COMMANDS[ns.command](ns, err)
    except CliError as exc:
        if _debug():
            traceback.print_exc(file=err)
        _fail(err, exc.message)
        return exc.code
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        return EXIT_OUTPUT
    except Exception as exc:
        if _debug():
            traceback.print_exc(file=err)
            _fail(err, f"internal error: {type(exc).__name__}: {exc}")
        else:
            text = " ".join(str(exc).split()) or "(no message)"
            _fail(
                err,
                f"internal error: {type(exc).__name__}: {text} "
                "(set GEOSMOOTH_DEBUG=1 for the traceback)",
            )
        return EXIT_INTERNAL


def _fail(err: TextIO, message: str) -> None:
    line = " ".join(message.split())  # exactly one line, whatever the message held
    try:
        err.write(f"geosmooth: error: {line}\n")
        err.flush()
    except (OSError, ValueError):
        pass


if __name__ == "__main__":
    raise SystemExit(main())
