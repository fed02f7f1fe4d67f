"""``geosmooth serve``: run the HTTP service (:func:`service.api.server.serve`).

The service checks what it can name precisely before it starts anything: the settings from
the environment (a bad ``GEOSMOOTH_*`` variable is one line naming it, exit status 2), a
non-loopback address without API keys (exit status 2 unless ``--insecure-no-auth``) and the
address itself (in use or not permitted: exit status 11, where uvicorn would exit with its own
status 3, which ``geosmooth`` documents as "input file missing").

On a terminal it prints one human line with the page's and the docs' addresses once the
server is ready (and logs warnings as text); elsewhere, or with ``--log-format json``, it logs
JSON lines (``GEOSMOOTH_LOG_FORMAT`` is the same setting).
"""

from __future__ import annotations

import argparse
from typing import TextIO

from service.cli.errors import CliError
from service.exit_codes import EXIT_ADDRESS, EXIT_OK, EXIT_USAGE

__all__ = ["run"]


def run(ns: argparse.Namespace, err: TextIO) -> int:
    """Run ``geosmooth serve`` until it is stopped; returns the exit status."""
    if ns.port is not None and not 0 < ns.port < 65536:
        raise CliError(f"--port: must be in 1..65535, got {ns.port}", EXIT_USAGE)
    if ns.workers is not None and ns.workers < 1:
        raise CliError(f"--workers: must be at least 1, got {ns.workers}", EXIT_USAGE)
    from service.api.server import serve
    from service.settings import ConfigError

    extra = {"log_format": ns.log_format} if getattr(ns, "log_format", None) else {}
    try:
        serve(
            ns.host,
            ns.port,
            ns.workers,
            ns.data_dir,
            insecure_no_auth=ns.insecure_no_auth,
            **extra,
        )
    except ConfigError as exc:
        raise CliError(exc.message, int(exc.exit_code)) from exc
    except SystemExit as exc:  # uvicorn's own exit: its startup failed (the log says why)
        if exc.code in (0, None):
            return EXIT_OK
        where = f"{ns.host or 'the configured host'}:{ns.port or 'port'}"
        raise CliError(
            f"the service on {where} could not start (uvicorn exited with "
            f"{exc.code}; see the log above)",
            EXIT_ADDRESS,
        ) from exc
    return EXIT_OK
