"""Where results go: the output format, the one file writer, the JSON report.

:func:`write_file` is the only way ``smooth`` and ``submit`` write a file. A regular file (or
a new one) is replaced atomically: the data go to a temporary file in the same directory, are
flushed to disk, and the temporary file is renamed over the target, so a reader never sees half
a file and a failure leaves the old file intact. A symbolic link is followed: the file it points
to is replaced and the link stays a link. Anything that is not a regular file (``/dev/null``,
``/dev/full``, a FIFO, a terminal, ``/dev/stdout``) is written in place, never replaced.
"""

from __future__ import annotations

import argparse
import contextlib
import inspect
import json
import math
import os
import sys
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from service.cli.errors import CliError, os_reason
from service.cli.params import literal_names
from service.exit_codes import EXIT_OUTPUT, EXIT_USAGE
from service.io.atomic import is_special, real_target, write_file

__all__ = [
    "check_crs",
    "check_format",
    "check_writable",
    "given_writer_options",
    "is_own_input",
    "output_format",
    "refuse_own_input",
    "write_file",
    "write_json_report",
    "write_output",
    "writer_options",
]


# --------------------------------------------------------------------------- own input


def is_own_input(source: str, target: str) -> bool:
    """Whether writing ``target`` would replace the file ``source``: the same path after links,
    or the same file by another name (a hard link: same device and inode)."""
    if "-" in (source, target):
        return False
    if os.path.realpath(source) == os.path.realpath(target):
        return True
    try:
        return os.path.samefile(source, target)
    except OSError:  # the output does not exist yet (or the input is gone: read fails later)
        return False


def refuse_own_input(source: str, target: str, overwrite: bool) -> None:
    """Exit status 2 when ``target`` is ``source`` (:func:`is_own_input`) without
    ``--overwrite``: a raw scan is never replaced by mistake (issue 41)."""
    if not overwrite and is_own_input(source, target):
        raise CliError(f"{source} would be overwritten by its own output {target}; give "
                       "another -o (or --overwrite to replace the input)", EXIT_USAGE)  # fmt: skip


# --------------------------------------------------------------------------- formats


def check_format(fmt: str | None, option: str) -> str | None:
    """``fmt`` if it is a format name of the registry (or ``None``); else exit status 2."""
    from service.io import FORMATS

    if fmt is not None and fmt not in FORMATS:
        raise CliError(f"{option}: must be one of {', '.join(FORMATS)}, got {fmt!r}", EXIT_USAGE)
    return fmt


def output_format(output: str, explicit: str | None) -> str | None:
    """The format to write: the output's extension, else ``--output-format``, else ``None``.

    ``None`` means "the input's format" (``-o -``, or a name without an extension).

    Raises
    ------
    CliError
        Exit status 2 when ``--output-format`` contradicts the extension, or the extension is
        not a format geosmooth writes and no ``--output-format`` says otherwise.
    """
    from service.io import UnsupportedFormat, detect_format

    check_format(explicit, "--output-format")
    by_ext: str | None = None
    if output != "-":
        with contextlib.suppress(UnsupportedFormat):
            by_ext = detect_format(output)
    if by_ext and explicit and by_ext != explicit:
        raise CliError(
            f"--output-format {explicit} contradicts the output file name {output!r} ({by_ext})",
            EXIT_USAGE,
        )
    if by_ext or explicit:
        return by_ext or explicit
    if output != "-" and Path(output).suffix:
        raise CliError(
            f"cannot tell the output format from {output!r}; give --output-format", EXIT_USAGE
        )
    return None


def check_crs(value: str | None) -> str | None:
    """The ``--crs`` value: ``utm`` or a projected CRS pyproj knows by its EPSG code.

    Raises
    ------
    CliError
        Exit status 2 for anything else (checked before any file is read).
    """
    if value is None:
        return None
    text = value.strip()
    if text.lower() == "utm":
        return "utm"
    code = text.upper().removeprefix("EPSG:")
    if not code.isdigit():
        raise CliError(
            f"--crs: must be an EPSG code (e.g. 32633 or EPSG:32633) or 'utm', got {value!r}",
            EXIT_USAGE,
        )
    import pyproj

    try:
        crs = pyproj.CRS.from_user_input(f"EPSG:{int(code)}")
    except pyproj.exceptions.CRSError:
        raise CliError(f"--crs: EPSG:{int(code)} is not a CRS pyproj knows", EXIT_USAGE) from None
    if not crs.is_projected:
        raise CliError(
            f"--crs: EPSG:{int(code)} ({crs.name}) is not a projected CRS (e.g. a UTM zone, "
            "EPSG:326zz / 327zz)",
            EXIT_USAGE,
        )
    return f"EPSG:{int(code)}"


def writer_options() -> dict[str, tuple[tuple[str, ...], str]]:
    """Options of :func:`service.io.write_geometry` that take a name, with their default.

    The keyword-only parameters typed as a ``Literal`` (``normals``, ``precision``): the
    ``smooth`` command offers each as ``--name``, so a writer option added in ``service.io``
    appears on the command line by itself.
    """
    from service.io import write_geometry

    hints = typing.get_type_hints(write_geometry)
    out = {}
    for name, parameter in inspect.signature(write_geometry).parameters.items():
        choices = literal_names(hints.get(name))
        if parameter.kind is parameter.KEYWORD_ONLY and choices:
            out[name] = (choices, str(parameter.default))
    return out


def given_writer_options(ns: argparse.Namespace) -> dict[str, Any]:
    """The writer options given on the command line (the writer's defaults apply otherwise)."""
    return {name: getattr(ns, name) for name in writer_options() if getattr(ns, name, None)}


# --------------------------------------------------------------------------- writing


def check_writable(target: str, what: str) -> None:
    """Fail early (exit status 6) when ``target`` cannot be written, before any work."""
    if target == "-":
        return
    if is_special(target):
        if Path(target).is_dir():
            raise CliError(f"cannot write {what} {target}: Is a directory", EXIT_OUTPUT)
        if not os.access(target, os.W_OK):
            raise CliError(f"cannot write {what} {target}: Permission denied", EXIT_OUTPUT)
        return
    parent = real_target(target).parent
    if not parent.is_dir():
        raise CliError(f"cannot write {what} {target}: No such directory {parent}", EXIT_OUTPUT)
    if not os.access(parent, os.W_OK | os.X_OK):
        raise CliError(f"cannot write {what} {target}: Permission denied", EXIT_OUTPUT)


def write_output(target: str, data: bytes, what: str) -> None:
    """:func:`write_file` for the CLI: ``-`` is stdout; failures are exit status 6."""
    try:
        if target == "-":
            sys.stdout.buffer.write(data)
            sys.stdout.buffer.flush()
        else:
            write_file(target, data)
    except OSError as exc:
        where = "to stdout" if target == "-" else target
        raise CliError(f"cannot write {what} {where}: {os_reason(exc)}", EXIT_OUTPUT) from exc


# --------------------------------------------------------------------------- report


def json_safe(value: Any) -> Any:
    """Make a report JSON-clean: numpy scalars/arrays to Python, non-finite floats to null."""
    if isinstance(value, Mapping):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(v) for v in value]
    if hasattr(value, "tolist") and not isinstance(value, str):
        return json_safe(value.tolist())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def write_json_report(target: str, report: Mapping[str, Any]) -> None:
    """Write a report as indented, strict JSON (exit status 6 on failure)."""
    text = json.dumps(json_safe(report), indent=2, allow_nan=False) + "\n"
    write_output(target, text.encode("utf-8"), "report")
