"""``geosmooth serve``: run the HTTP service (:func:`service.api.server.serve`).

Before the service starts, the command checks what it can name precisely: the options, the
settings from the environment (a bad ``GEOSMOOTH_*`` variable is one line naming it, exit
status 2) and the address (in use or not permitted: exit status 11, where uvicorn would exit
with its own status 3, which ``geosmooth`` documents as "input file missing").
"""

from __future__ import annotations

import argparse
import os
import socket
from typing import TextIO

from service.exit_codes import EXIT_ADDRESS, EXIT_OK, EXIT_USAGE

from .errors import CliError, os_reason

__all__ = ["check_address", "check_settings", "run"]


def check_settings(**overrides: object) -> None:
    """Load the settings once; a bad environment variable is a :class:`CliError` naming it."""
    from pydantic import ValidationError

    from service.settings import Settings

    try:
        Settings(**overrides)  # type: ignore[arg-type]
    except ValidationError as exc:
        prefix = str(Settings.model_config.get("env_prefix") or "")
        parts = []
        for error in exc.errors(include_url=False):
            name = str(error["loc"][0]) if error.get("loc") else "?"
            var = f"{prefix}{name}".upper()
            shown = f"{var}={os.environ[var]!r}" if var in os.environ else var
            msg = str(error.get("msg", "invalid value")).replace("Input should be", "must be")
            parts.append(f"{shown}: {msg}")
        raise CliError("invalid configuration: " + "; ".join(parts), EXIT_USAGE) from exc


def check_address(host: str, port: int) -> None:
    """Bind ``host:port`` as uvicorn will (then let it go); failures are exit status 11."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((host, port))
        except OSError as exc:
            reason = exc.strerror if isinstance(exc, socket.gaierror) else os_reason(exc)
            raise CliError(f"cannot listen on {host}:{port}: {reason}", EXIT_ADDRESS) from exc


def run(ns: argparse.Namespace, err: TextIO) -> int:
    """Run ``geosmooth serve`` until it is stopped; returns the exit status."""
    if not 0 < ns.port < 65536:
        raise CliError(f"--port: must be in 1..65535, got {ns.port}", EXIT_USAGE)
    if ns.workers is not None and ns.workers < 1:
        raise CliError(f"--workers: must be at least 1, got {ns.workers}", EXIT_USAGE)
    overrides = {"workers": ns.workers, "data_dir": ns.data_dir}
    check_settings(**{k: v for k, v in overrides.items() if v is not None})
    check_address(ns.host, ns.port)
    from service.api.server import serve

    try:
        serve(ns.host, ns.port, ns.workers, ns.data_dir)
    except SystemExit as exc:  # uvicorn's own exit: its startup failed (the log says why)
        if exc.code in (0, None):
            return EXIT_OK
        raise CliError(
            f"the service on {ns.host}:{ns.port} could not start (uvicorn exited with "
            f"{exc.code}; see the log above)",
            EXIT_ADDRESS,
        ) from exc
    return EXIT_OK
