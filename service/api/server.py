"""Run the HTTP service with uvicorn (``geosmooth serve`` calls :func:`serve`).

Before anything is started, :func:`serve` reads and checks the settings (a
:class:`~service.settings.ConfigError` names the environment variable), refuses to serve a
non-loopback address without API keys unless told ``insecure_no_auth``
(:func:`check_bind`), and binds the socket itself, so a port in use is a
:class:`AddressUnavailable` error (one line, its own exit code) instead of a log line.

Exit codes of ``serve`` (``exit_code`` of the errors): 0 stopped by SIGINT/SIGTERM;
2 (``EXIT_USAGE``) invalid setting, keys file or insecure bind; 11 (``EXIT_ADDRESS``) the
address cannot be bound (in use, not permitted, unknown host); 14 (``EXIT_STORE``) the job
database is damaged (SQLite's ``quick_check`` fails, or the file is no database).
"""

from __future__ import annotations

import argparse
import contextlib
import ipaddress
import resource
import socket
import sys
from collections.abc import Sequence
from typing import Any, ClassVar

import uvicorn

from service.api.http.auth import KeyRing
from service.api.http.logs import configure_logging, get_logger
from service.api.http.protocol import guarded_protocol
from service.exit_codes import EXIT_ADDRESS, EXIT_STORE
from service.settings import ConfigError, Settings, load_settings

__all__ = [
    "AddressUnavailable",
    "InsecureBind",
    "StoreUnusable",
    "announcement",
    "base_url",
    "check_bind",
    "is_loopback",
    "log_mode",
    "main",
    "serve",
]

log = get_logger("geosmooth.api")
#: Listen backlog (the kernel caps it at net.core.somaxconn): a deep accept queue, so a
#: connection flood does not make the kernel drop other clients' SYNs (a 1-3 s retry each).
_BACKLOG = 4096
#: Connections asyncio accepts per event-loop turn (it reuses uvicorn's ``backlog`` for that):
#: small, so a flood's accepts interleave with the requests already in.
_ACCEPT_BATCH = 64


class _Server(uvicorn.Server):
    """uvicorn's server, with the deep listen queue restored after its startup, and the
    ``announce`` line (if any) printed once it is ready."""

    announce: str | None = None

    async def startup(self, sockets: list[socket.socket] | None = None) -> None:
        await super().startup(sockets=sockets)
        for sock in sockets or []:
            sock.listen(_BACKLOG)  # uvicorn set it to the accept batch size
        if self.started and self.announce:
            print(self.announce, file=sys.stderr, flush=True)


def base_url(host: str, port: int) -> str:
    """The address to open in a browser (``localhost`` for the any-address binds)."""
    name = host.strip().strip("[]")
    if name in ("", "0.0.0.0", "::"):
        name = "localhost"
    elif ":" in name:
        name = f"[{name}]"
    return f"http://{name}:{port}"


def announcement(host: str, port: int) -> str:
    """The one human line of ``geosmooth serve`` on a terminal."""
    url = base_url(host, port)
    return f"geosmooth is serving {url}/ (API docs: {url}/docs); press Ctrl-C to stop"


def log_mode(settings: Settings, terminal: bool) -> tuple[str, str, bool]:
    """(log format, log level, whether to print the human line) for ``settings``.

    ``log_format="auto"``: on a terminal, the human line and text logs of warnings and errors
    (unless ``GEOSMOOTH_LOG_LEVEL`` says otherwise); elsewhere JSON, as ``log_format="json"``.
    """
    if settings.log_format != "auto":
        return settings.log_format, settings.log_level, False
    if not terminal:
        return "json", settings.log_level, False
    level = settings.log_level if "log_level" in settings.model_fields_set else "warning"
    return "console", level, True


class InsecureBind(ConfigError):
    """A non-loopback address without API keys, and no explicit ``insecure_no_auth``."""

    code = "insecure-bind"
    title = "Refusing to serve without authentication"


class AddressUnavailable(ConfigError):
    """The address cannot be bound (port in use, permission, unknown host)."""

    code = "address-unavailable"
    title = "Address unavailable"
    exit_code: ClassVar[int] = EXIT_ADDRESS


class StoreUnusable(ConfigError):
    """The job database is damaged (:class:`~service.jobs.errors.StoreDamaged`)."""

    code = "store-damaged"
    title = "Job database damaged"
    exit_code: ClassVar[int] = EXIT_STORE


def _check_store(settings: Settings) -> None:
    from service.jobs import check_store
    from service.jobs.errors import StoreDamaged

    try:
        check_store(settings)
    except StoreDamaged as exc:
        raise StoreUnusable(exc.message, field="GEOSMOOTH_DATA_DIR") from None


def is_loopback(host: str) -> bool:
    """Whether ``host`` only accepts connections from this machine."""
    name = host.strip().strip("[]").lower()
    if name == "localhost":
        return True
    try:
        return ipaddress.ip_address(name).is_loopback
    except ValueError:
        return False


def check_bind(host: str, keys_configured: bool, insecure_no_auth: bool = False) -> None:
    """Refuse to serve ``host`` to the network without API keys.

    Raises
    ------
    InsecureBind
        ``host`` is not a loopback address, no key is configured and ``insecure_no_auth`` is
        false (``--insecure-no-auth`` / ``GEOSMOOTH_INSECURE_NO_AUTH=true``).
    """
    if keys_configured or insecure_no_auth or is_loopback(host):
        return
    raise InsecureBind(
        f"refusing to serve {host} without API keys: set GEOSMOOTH_API_KEYS or "
        "GEOSMOOTH_API_KEYS_FILE, or pass --insecure-no-auth to allow anyone who can reach "
        "the port to submit, read and delete jobs",
        field="GEOSMOOTH_HOST",
    )


def _bind(host: str, port: int, backlog: int) -> socket.socket:
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
        family, kind, proto, _, address = infos[0]
        sock = socket.socket(family, kind, proto)
    except (OSError, IndexError) as exc:
        message = f"cannot bind {host}:{port}: {exc}"
        raise AddressUnavailable(message, field="GEOSMOOTH_HOST") from None
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(address)
        sock.listen(backlog)
    except OSError as exc:
        sock.close()
        why = exc.strerror or str(exc)
        message = f"cannot bind {host}:{port}: {why}"
        raise AddressUnavailable(message, field="GEOSMOOTH_PORT") from None
    sock.set_inheritable(True)
    return sock


def _raise_open_files_limit(wanted: int) -> None:
    """Allow ``wanted`` open files (up to the hard limit): connections are files."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    target = wanted if hard == resource.RLIM_INFINITY else min(wanted, hard)
    if soft != resource.RLIM_INFINITY and soft < target:
        with contextlib.suppress(ValueError, OSError):
            resource.setrlimit(resource.RLIMIT_NOFILE, (target, hard))


def uvicorn_config(app: Any, settings: Settings) -> uvicorn.Config:
    """uvicorn settings of the service (connection bounds, timeouts, no access log)."""
    return uvicorn.Config(
        app,
        http=guarded_protocol(
            settings.max_connections,
            settings.max_connections_per_client,
            settings.timeout_request_header,
        ),
        timeout_keep_alive=int(max(1, round(settings.timeout_keep_alive))),
        timeout_graceful_shutdown=int(max(1, round(settings.timeout_graceful_shutdown))),
        h11_max_incomplete_event_size=16 * 1024,
        backlog=_ACCEPT_BATCH,
        log_config=None,
        access_log=False,
        proxy_headers=False,
        server_header=False,
        lifespan="on",
    )


def serve(
    host: str | None = None,
    port: int | None = None,
    workers: int | None = None,
    data_dir: str | None = None,
    *,
    insecure_no_auth: bool = False,
    **settings_overrides: Any,
) -> None:
    """Serve the API until SIGINT / SIGTERM (requests get ``timeout_graceful_shutdown`` s).

    Parameters
    ----------
    host, port : str, int, optional
        Address (default: settings ``host``/``port``, ``GEOSMOOTH_HOST``/``GEOSMOOTH_PORT``).
    workers : int, optional
        Solver worker processes of the embedded job queue (default: setting ``workers``).
    data_dir : str, optional
        Job store directory (default: setting ``data_dir``).
    insecure_no_auth : bool
        Serve a non-loopback address without API keys.
    **settings_overrides
        Any other :class:`~service.settings.Settings` field.

    Raises
    ------
    ConfigError
        Invalid settings, :class:`InsecureBind` or :class:`AddressUnavailable` (nothing was
        started; ``exc.exit_code`` is the process's exit status).
    """
    given = {"host": host, "port": port, "workers": workers, "data_dir": data_dir}
    overrides = {**settings_overrides, **{k: v for k, v in given.items() if v is not None}}
    settings = load_settings(**overrides)
    fmt, level, human = log_mode(settings, sys.stderr.isatty())
    configure_logging(level, fmt)
    keys = KeyRing.from_settings(settings)
    check_bind(settings.host, keys.enabled, insecure_no_auth or settings.insecure_no_auth)
    _check_store(settings)
    _raise_open_files_limit(settings.max_connections + 1024)
    sock = _bind(settings.host, settings.port, _BACKLOG)
    from service.api.app import create_app  # after the checks: a bad config starts nothing

    app = create_app(settings)
    log.info(
        "server.start",
        host=settings.host,
        port=settings.port,
        keys=len(keys),
        workers=settings.workers,
    )
    server = _Server(uvicorn_config(app, settings))
    server.announce = announcement(settings.host, settings.port) if human else None
    server.run(sockets=[sock])


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m service.api.server [--host H] [--port P] [--workers N] [--data-dir D]``."""
    parser = argparse.ArgumentParser(prog="python -m service.api.server", description=__doc__)
    parser.add_argument("--host", default=None)
    parser.add_argument("--port", type=int, default=None)
    parser.add_argument("--workers", type=int, default=None)
    parser.add_argument("--data-dir", default=None)
    parser.add_argument("--insecure-no-auth", action="store_true")
    parser.add_argument("--log-format", choices=("auto", "json", "console"), default=None)
    ns = parser.parse_args(argv)
    extra = {"log_format": ns.log_format} if ns.log_format else {}
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
        print(f"geosmooth serve: {exc.message}", file=sys.stderr)
        return int(exc.exit_code)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
