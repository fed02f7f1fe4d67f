"""The ``geosmooth`` command line: ``smooth`` a file, ``serve`` the HTTP API, ``submit`` to it.

``geosmooth smooth INPUT -o OUTPUT --tau T`` reads a mesh, polyline network or point cloud
(``service.io``), smooths it with :func:`service.core.smooth` and writes the result in the same
vertex order. Every failure is one line on stderr and a documented exit status
(:mod:`service.exit_codes`); ``GEOSMOOTH_DEBUG=1`` adds the traceback.

Modules: :mod:`.main` (dispatch, error handling), :mod:`.parser` (commands and their options),
:mod:`.params` (options generated from ``SmoothingParams``), :mod:`.output` (output format,
the file writer, the report), :mod:`.progress` (progress line, summary), :mod:`.batch`
(several inputs), and one module per command (:mod:`.smooth`, :mod:`.serve`, :mod:`.submit`,
:mod:`.worker`, :mod:`.completion`), imported only when it runs.
``params_from_args`` and ``read_fixed_indices`` load pydantic and numpy, so they are imported
on first access (``geosmooth --help`` loads neither).
"""

from typing import Any

from service.cli.errors import CliError
from service.cli.main import main
from service.cli.parser import build_parser
from service.exit_codes import EXIT_CODES, SERVE_EXIT_CODES, SUBMIT_EXIT_CODES

__all__ = [
    "EXIT_CODES",
    "SERVE_EXIT_CODES",
    "SUBMIT_EXIT_CODES",
    "CliError",
    "build_parser",
    "main",
    "params_from_args",
    "read_fixed_indices",
]


def __getattr__(name: str) -> Any:
    if name == "params_from_args":
        from service.cli.params import params_from_args

        return params_from_args
    if name == "read_fixed_indices":
        from service.cli.smooth import read_fixed_indices

        return read_fixed_indices
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
