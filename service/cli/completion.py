"""``geosmooth completion bash|zsh``: a shell completion script, generated from the parser.

`shtab <https://github.com/iterative/shtab>`_ writes the script from the full argument parser
(:func:`service.cli.parser.build_parser`), so every command, option and choice of this version
is completed without a hand-kept list; the file arguments complete file names.
"""

from __future__ import annotations

import argparse
import sys
from typing import TextIO

from service.exit_codes import EXIT_OK

__all__ = ["FILE_ARGUMENTS", "run", "script"]

#: Destinations of the arguments that name files (completed as file names).
FILE_ARGUMENTS = frozenset({"input", "output", "report", "fixed", "data_dir"})


def _mark(parser: argparse.ArgumentParser) -> None:
    """File arguments complete file names; options whose values the model checks (shown as
    ``{a,b,c}``, no argparse ``choices``) complete those values."""
    import shtab

    for action in parser._actions:
        if action.dest in FILE_ARGUMENTS:
            action.complete = shtab.FILE  # type: ignore[attr-defined]
        shown = action.metavar if isinstance(action.metavar, str) else ""
        if action.choices is None and shown.startswith("{") and shown.endswith("}"):
            action.choices = shown[1:-1].split(",")
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                _mark(sub)


def script(shell: str) -> str:
    """The completion script of ``geosmooth`` for ``shell`` (``bash`` or ``zsh``)."""
    import shtab

    from service.cli.parser import build_parser

    parser = build_parser()
    _mark(parser)
    return str(shtab.complete(parser, shell=shell))


def run(ns: argparse.Namespace, err: TextIO) -> int:
    """Print the script on stdout."""
    text = script(ns.shell)
    sys.stdout.write(text if text.endswith("\n") else text + "\n")
    return EXIT_OK
