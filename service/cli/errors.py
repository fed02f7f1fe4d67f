"""How a failure becomes one line on stderr and an exit status.

Typed errors of the engine, the file formats and the settings carry their exit status as the
class attribute ``exit_code`` (:mod:`service.core.errors`, :mod:`service.io.errors`); the CLI
reads it from there (:func:`exit_code_of`) and never keeps a table of error classes.
:class:`CliError` is for what only the command line knows (a bad option, an unwritable output).
"""

from __future__ import annotations

import sys
from typing import TextIO

__all__ = ["CliError", "exit_code_of", "fail", "message_of", "os_reason"]


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
