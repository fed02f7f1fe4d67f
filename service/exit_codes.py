"""Exit statuses of the ``geosmooth`` command: the one table of their meanings.

Typed errors carry their status as metadata, a plain ``int`` class attribute ``exit_code``
(``GeometryError`` 4, ``SolverError`` 5 in :mod:`service.core.errors`; ``FormatError`` 3 in
:mod:`service.io.errors`; ``JobsError`` 1 / 2 in :mod:`service.jobs.errors`; ``ConfigError`` 2
in :mod:`service.settings`); the CLI reads it off the exception
(:func:`service.cli.errors.exit_code_of`) and documents it here. Nothing below the CLI imports
this module (``tests/test_architecture.py`` checks that every ``exit_code`` of those classes is a
status of this table).

Kept free of heavy imports, so ``geosmooth --help`` lists them without loading the HTTP client
or the engine.
"""

from __future__ import annotations

EXIT_OK = 0
EXIT_INTERNAL = 1
EXIT_USAGE = 2
EXIT_INPUT = 3
EXIT_GEOMETRY = 4
EXIT_SOLVER = 5
EXIT_OUTPUT = 6
EXIT_SHAPE = 12
EXIT_LIMIT = 13
EXIT_INTERRUPTED = 130

#: Exit status -> meaning; printed in ``geosmooth --help``.
EXIT_CODES: dict[int, str] = {
    EXIT_OK: "success",
    EXIT_INTERNAL: "unexpected internal error (GEOSMOOTH_DEBUG=1 shows the traceback)",
    EXIT_USAGE: "invalid command line or parameter value (e.g. --tau -1, --tau with --lam)",
    EXIT_INPUT: "input file missing, unreadable, malformed or in an unsupported format",
    EXIT_GEOMETRY: "invalid geometry, or a parameter this geometry cannot take "
    "(e.g. tau outside (0, phi(0)); the message gives the valid range)",
    EXIT_SOLVER: "the linear solver failed",
    EXIT_OUTPUT: "cannot write the output or report file",
    EXIT_SHAPE: "--strict: smoothing lost shape (a shape check warned); nothing was written",
    EXIT_LIMIT: "the run used its CPU time limit (--time-limit); nothing was written",
    EXIT_INTERRUPTED: "interrupted (Ctrl-C)",
}

EXIT_SERVER = EXIT_INTERNAL  # submit: the server answered something unexpected (5xx)
EXIT_UNREACHABLE = 7
EXIT_REJECTED = 8
EXIT_JOB_FAILED = 9
EXIT_CANCELLED = 10

#: Further statuses of ``geosmooth submit`` (``service.cli.submit``).
SUBMIT_EXIT_CODES: dict[int, str] = {
    EXIT_UNREACHABLE: "submit: the server cannot be reached",
    EXIT_REJECTED: "submit: the server rejected the input or the parameters",
    EXIT_JOB_FAILED: "submit: the job failed on the server",
    EXIT_CANCELLED: "submit: the job was cancelled",
}

EXIT_ADDRESS = 11
EXIT_STORE = 14

#: Further statuses of ``geosmooth serve`` (``service.api.server``).
SERVE_EXIT_CODES: dict[int, str] = {
    EXIT_USAGE: "serve: invalid setting (the message names the GEOSMOOTH_ variable), keys "
    "file, or a non-loopback address without API keys (see --insecure-no-auth)",
    EXIT_ADDRESS: "serve: the address cannot be bound (port in use, permission, unknown host)",
    EXIT_STORE: "serve: the job database is damaged (SQLite's quick_check fails, or the file "
    "is no database); nothing was started or deleted",
}
