"""``geosmooth``'s entry point: parse, run one command, turn any failure into one line.

A failure's exit status is the ``exit_code`` its class declares (the typed errors of the
engine, the readers, the settings and :class:`~service.cli.errors.CliError`); the line names
the option at fault when the error's ``field`` is a smoothing parameter, else the input file.
Anything else is an internal error (exit status 1), also one line unless ``GEOSMOOTH_DEBUG``
is set.
"""

from __future__ import annotations

import argparse
import importlib
import sys
import traceback
from collections.abc import Sequence
from typing import TextIO

from service.cli.errors import debugging, fail, failure
from service.cli.parser import build_parser, command_of
from service.exit_codes import EXIT_INTERRUPTED, EXIT_OUTPUT, EXIT_USAGE

__all__ = ["main"]

#: command -> module with ``run(ns, err) -> int`` (imported when the command runs, so that
#: ``smooth`` never loads the HTTP stack).
_COMMANDS = {
    "smooth": ".batch",  # several inputs, or the one file of .smooth
    "info": ".info",
    "serve": ".serve",
    "submit": ".submit",
    "worker": ".worker",
    "completion": ".completion",
}


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``geosmooth``.

    Parameters
    ----------
    argv : sequence of str, optional
        Arguments without the program name; default ``sys.argv[1:]``.

    Returns
    -------
    int
        Exit status (see :mod:`service.exit_codes`).
    """
    err = sys.stderr
    ns: argparse.Namespace | None = None
    args = list(argv) if argv is not None else sys.argv[1:]
    try:
        if args[:1] == ["worker"]:  # the worker parses its own options (RQ's, --help included)
            ns = argparse.Namespace(command="worker", worker_args=args[1:])
            return int(importlib.import_module(".worker", __package__).run(ns, err))
        try:
            command = command_of(args)
            ns = build_parser(full=() if command is None else (command,)).parse_args(args)
        except SystemExit as exc:  # --help / --version
            return int(exc.code or 0) if isinstance(exc.code, int | None) else EXIT_USAGE
        if ns.command in ("smooth", "info"):
            from service.cli.params import threads

            threads()
        module = importlib.import_module(_COMMANDS[ns.command], __package__)
        return int(module.run(ns, err))
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        return EXIT_OUTPUT
    except Exception as exc:
        return _report(exc, ns, err)


def _report(exc: Exception, ns: argparse.Namespace | None, err: TextIO) -> int:
    """Print one line for ``exc``; its exit status."""
    if debugging():
        traceback.print_exc(file=err)
    code, line = failure(exc, ns)
    fail(line, err)
    return code
