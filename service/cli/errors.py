"""How a failure becomes one line on stderr and an exit status.

Typed errors of the engine, the file formats and the settings carry their exit status as the
class attribute ``exit_code`` (:mod:`service.core.errors`, :mod:`service.io.errors`); the CLI
reads it from there (:func:`exit_code_of`) and never keeps a table of error classes.
:class:`CliError` is for what only the command line knows (a bad option, an unwritable output).
:func:`failure` turns any exception into the exit status and the one line (naming the option at
fault or the input file), for ``main`` and for each file of a batch.
"""

from __future__ import annotations

import argparse
import os
import sys
from typing import TextIO

from service.exit_codes import EXIT_INTERNAL

__all__ = [
    "CliError",
    "debugging",
    "exit_code_of",
    "fail",
    "failure",
    "message_of",
    "option_name",
    "os_reason",
]


class CliError(Exception):
    """A failure the CLI reports as one line and an exit status.

    Parameters
    ----------
    message : str
        The line after ``geosmooth: error: ``.
    code : int
        Exit status, one of the documented ones (:mod:`service.exit_codes`).
    """

    def __init__(self, message: str, code: int) -> None:
        super().__init__(message)
        self.message = message
        self.exit_code = code

    @property
    def code(self) -> int:
        """The exit status (alias of ``exit_code``)."""
        return self.exit_code

    @classmethod
    def located(cls, exc: BaseException, where: str) -> CliError:
        """A typed error (with ``exit_code``) as ``where: message``, keeping its status."""
        code = exit_code_of(exc)
        if code is None:
            raise TypeError(f"{type(exc).__name__} has no exit_code") from exc
        return cls(f"{where}: {message_of(exc)}", code)


def exit_code_of(exc: BaseException) -> int | None:
    """The exit status an error class declares (attribute ``exit_code``), else ``None``."""
    code = getattr(exc, "exit_code", None)
    return code if isinstance(code, int) and not isinstance(code, bool) else None


def message_of(exc: BaseException) -> str:
    """The error's own one-line message (``.message`` when it has one)."""
    text = getattr(exc, "message", None) or str(exc) or type(exc).__name__
    return " ".join(str(text).split())


def os_reason(exc: BaseException) -> str:
    """``No such file or directory`` rather than ``[Errno 2] ...: 'x'``."""
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror
    return str(exc) or type(exc).__name__


def fail(message: str, err: TextIO | None = None) -> None:
    """Write ``geosmooth: error: <message>`` as exactly one line."""
    stream = err if err is not None else sys.stderr
    line = " ".join(message.split())
    try:
        stream.write(f"geosmooth: error: {line}\n")
        stream.flush()
    except (OSError, ValueError):
        pass


def option_name(field: str) -> str:
    """``max_iterations`` -> ``--max-iterations``."""
    return "--" + field.replace("_", "-")


def debugging() -> bool:
    """Whether ``GEOSMOOTH_DEBUG`` asks for tracebacks."""
    return os.environ.get("GEOSMOOTH_DEBUG", "").strip() not in ("", "0", "false", "no")


def _where(exc: BaseException, ns: argparse.Namespace | None) -> str | None:
    """What a typed error is about: ``--option`` for a parameter, else the input file."""
    from service.core.params import SmoothingParams

    field = str(getattr(exc, "field", "") or "")
    name = field.removeprefix("params.")
    if field.startswith("params.") and name in SmoothingParams.model_fields:
        return option_name(name)
    source = getattr(ns, "input", None)
    return str(source) if source else None


def _typed_message(exc: BaseException, ns: argparse.Namespace | None) -> str:
    if isinstance(exc, CliError):
        return exc.message
    where = _where(exc, ns)
    return f"{where}: {message_of(exc)}" if where else message_of(exc)


def failure(exc: BaseException, ns: argparse.Namespace | None) -> tuple[int, str]:
    """The exit status and the one line (without ``geosmooth: error:``) of a failure."""
    code = exit_code_of(exc)
    if code is not None:
        return code, _typed_message(exc, ns)
    text = message_of(exc) if str(exc) else "(no message)"
    hint = "" if debugging() else " (set GEOSMOOTH_DEBUG=1 for the traceback)"
    return EXIT_INTERNAL, f"internal error: {type(exc).__name__}: {text}{hint}"
