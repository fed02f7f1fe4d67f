"""What every ``geosmooth`` parser shares: the parser class, help texts, the exit status table.

Kept free of heavy imports (``geosmooth --help`` loads neither pydantic nor numpy).
"""

from __future__ import annotations

import argparse
import textwrap
from collections.abc import Mapping
from typing import NoReturn

from service.cli.errors import CliError
from service.exit_codes import EXIT_CODES, EXIT_USAGE

__all__ = ["HELP", "Parser", "epilog", "formats", "version", "wrap"]

EXAMPLES = (
    "geosmooth smooth bunny.ply -o bunny-smooth.ply --tau 2e-4 --report report.json",
    "geosmooth smooth track.obj -o track-smooth.obj --rms 3 --fix-boundary",
    "geosmooth smooth 'scans/*.laz' -o smoothed/ --name '{stem}-smooth.{ext}' -j 0",
    "geosmooth smooth track.gpx -o track.las --rms 3 --crs utm",
    "geosmooth info scan.xyz        # noise estimate, valid tau / rms ranges",
    "geosmooth serve --port 8000",
    "geosmooth submit bunny.ply --server http://127.0.0.1:8000 -o out.ply --tau 2e-4",
)


#: One-line help of each command (shown by ``geosmooth --help``).
HELP = {
    "smooth": "smooth a file",
    "info": "describe a file and the smoothing budgets it admits (nothing is smoothed)",
    "serve": "run the HTTP service",
    "submit": "smooth a file on a running geosmooth server",
    "worker": "run a worker of the distributed (Redis + RQ) job queue",
    "completion": "print a shell completion script (bash or zsh)",
}


class Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors are one line (no usage block) and do not exit."""

    def error(self, message: str) -> NoReturn:
        raise CliError(f"{message} (see '{self.prog} --help')", EXIT_USAGE)


def version() -> str:
    """The installed geosmooth version (``unknown`` in an uninstalled source tree)."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as dist_version

    try:
        return dist_version("geosmooth")
    except PackageNotFoundError:
        return "unknown"


def wrap(text: str) -> str:
    return textwrap.fill(text, 78)


def epilog(*extra: Mapping[int, str]) -> str:
    table = dict(EXIT_CODES)
    for more in extra:
        for code, text in more.items():
            table[code] = f"{table[code]}; {text}" if code in table else text
    codes = "\n".join(
        textwrap.fill(text, 78, initial_indent=f"  {code:>3}  ", subsequent_indent=" " * 7)
        for code, text in sorted(table.items())
    )
    examples = "\n".join(f"  {line}" for line in EXAMPLES)
    return (
        f"examples:\n{examples}\n\nexit status:\n{codes}\n\n"
        "Errors are one line on stderr; set GEOSMOOTH_DEBUG=1 for a traceback."
    )


def formats() -> str:
    from service.io import FORMATS

    return "{" + ",".join(FORMATS) + "}"
