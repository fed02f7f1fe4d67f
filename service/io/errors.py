"""Errors raised while reading or writing geometry files.

A :class:`FormatError` means the bytes are not a valid file of the format (bad header, truncated
data, a non-numeric token, an index outside the vertex list, ...). An :class:`UnsupportedFormat`
means geosmooth does not read or write the format at all (GPX, GeoJSON, DXF, unknown extensions);
its message says what to convert the data to. Title, HTTP status (400 / 415) and CLI exit
status are class attributes.

Both carry the same machine-readable surface as the engine's errors (``.message``, ``.field``,
``.code``, ``.to_dict()``) so callers can report them uniformly, but they are not
``GeosmoothError`` subclasses: a malformed file is not a geometry problem.
"""

from __future__ import annotations

from typing import ClassVar

__all__ = ["FormatError", "MissingDependency", "UnsupportedFormat"]


class FormatError(ValueError):
    """A malformed file: one line saying what is wrong and where.

    Parameters
    ----------
    message : str
        Human readable, one line. For text formats it starts with the line number.
    fmt : str, optional
        The format being read or written (``"ply"``, ``"obj"``, ``"xyz"``, ``"json"``), if known.
    line : int, optional
        1-based line number of the offending line (text formats only).

    Attributes
    ----------
    message, fmt, line
        As given.
    field : str
        Always ``"file"`` (the part of a request at fault).
    code : str
        ``"format-error"`` (``"unsupported-format"`` for :class:`UnsupportedFormat`).
    """

    code: ClassVar[str] = "format-error"
    field: str = "file"
    #: Problem title, HTTP status and CLI exit status (read by the API, the jobs and the CLI).
    title: ClassVar[str] = "Malformed input file"
    status: ClassVar[int] = 400
    exit_code: ClassVar[int] = 3  # see the CLI's table, service/exit_codes.py

    def __init__(self, message: str, *, fmt: str | None = None, line: int | None = None) -> None:
        message = " ".join(message.split())  # always one line
        super().__init__(message)
        self.message = message
        self.fmt = fmt
        self.line = int(line) if line is not None else None

    def to_dict(self) -> dict[str, object]:
        """Machine-readable form (used in job records and problem details)."""
        out: dict[str, object] = {"code": self.code, "message": self.message, "field": self.field}
        if self.fmt is not None:
            out["format"] = self.fmt
        if self.line is not None:
            out["line"] = self.line
        return out


class UnsupportedFormat(FormatError):
    """A format geosmooth does not read or write; the message says what to convert to."""

    code = "unsupported-format"
    field = "format"
    title = "Unsupported format"
    status = 415


class MissingDependency(Exception):
    """A package the server needs to read or write a format is not installed (issue 41).

    A server-side fault, never the input's: HTTP 500 naming the package, CLI exit status 1
    (internal), unlike :class:`FormatError` (400, the user's file).

    Parameters
    ----------
    package : str
        The distribution to install (``"pillow"``), as pip names it.
    fmt : str, optional
        The format being read or written.
    """

    code: ClassVar[str] = "missing-dependency"
    field: str | None = None
    title: ClassVar[str] = "A server package is missing"
    status: ClassVar[int] = 500
    exit_code: ClassVar[int] = 1  # internal: see the CLI's table, service/exit_codes.py

    def __init__(self, package: str, *, fmt: str | None = None) -> None:
        what = f"{fmt.upper()} files" if fmt else "this format"
        message = (
            f"the Python package {package!r} that {what} need is not installed on this "
            f"machine (an installation fault, not the input's: pip install {package})"
        )
        super().__init__(message)
        self.message = message
        self.package = package
        self.fmt = fmt

    @classmethod
    def of(cls, exc: ImportError, fmt: str | None = None) -> MissingDependency:
        """The missing package of an ``ImportError`` (its module's distribution name)."""
        import re

        named = re.search(r"named '([\w.]+)'|import of ([\w.]+)", str(exc))
        module = (exc.name or (named and (named[1] or named[2])) or "unknown").split(".")[0]
        return cls(_DISTRIBUTIONS.get(module, module), fmt=fmt)

    def to_dict(self) -> dict[str, object]:
        """Machine-readable form (problem details, job records)."""
        out: dict[str, object] = {"code": self.code, "message": self.message}
        out["package"] = self.package
        if self.fmt is not None:
            out["format"] = self.fmt
        return out


#: Import names whose pip distribution is named otherwise.
_DISTRIBUTIONS = {"PIL": "pillow", "lzf": "python-neo-lzf", "yaml": "pyyaml"}
