"""Run the HTTP service with uvicorn (``geosmooth serve``)."""

from __future__ import annotations

import argparse
import logging
from collections.abc import Sequence
from typing import Any

import uvicorn

from service.api.app import create_app
from service.settings import Settings

__all__ = ["main", "serve"]


def serve(
    host: str = "127.0.0.1",
    port: int = 8000,
    workers: int | None = None,
    data_dir: str | None = None,
    **settings_overrides: Any,
) -> None:
    """Serve the API until interrupted (SIGINT / SIGTERM stop the queue cleanly).

    Parameters
    ----------
    host, port : str, int
        Address to listen on.
    workers : int, optional
        Solver worker processes of the embedded job queue (default: setting ``workers``).
        The HTTP server itself is one process: the queue is embedded in it.
    data_dir : str, optional
        Job store directory (default: setting ``data_dir``, env ``GEOSMOOTH_DATA_DIR``).
    **settings_overrides
        Any other :class:`~service.settings.Settings` field.
    """
    overrides: dict[str, Any] = dict(settings_overrides)
    if workers is not None:
        overrides["workers"] = workers
    if data_dir is not None:
        overrides["data_dir"] = data_dir
    settings = Settings(**overrides)
    logging.basicConfig(
        level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s"
    )
    app = create_app(settings)
    uvicorn.run(app, host=host, port=port, log_level="info", proxy_headers=False)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m service.api.server [--host H] [--port P] [--workers N] [--data-dir D]``."""
    parser = argparse.ArgumentParser(prog="python -m service.api.server", description=__doc__)
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, default=8000)
    parser.add_argument("--workers", type=int, default=None)
    parser.add_argument("--data-dir", default=None)
    ns = parser.parse_args(argv)
    serve(ns.host, ns.port, ns.workers, ns.data_dir)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
