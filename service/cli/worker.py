"""``geosmooth worker``: an RQ worker of the distributed backend (``GEOSMOOTH_QUEUE=rq``).

The worker itself is :func:`service.jobs.distributed.worker.main`; this command forwards its options
(``--burst``, ``--max-jobs``, ``--name``, ``--log-level``) and reads the same ``GEOSMOOTH_*``
settings as ``geosmooth serve``. RQ and Redis are the ``distributed`` extra, which ``make run``
does not install: without them the command says so in one line (exit status 2).
"""

from __future__ import annotations

import argparse
import importlib.util
from typing import TextIO

from service.cli.errors import CliError
from service.exit_codes import EXIT_USAGE

__all__ = ["MISSING_EXTRA", "run"]

MISSING_EXTRA = (
    "geosmooth worker needs the distributed extra: pip install 'geosmooth[distributed]' "
    "and GEOSMOOTH_QUEUE=rq"
)


def _distributed_installed() -> bool:
    return all(importlib.util.find_spec(name) is not None for name in ("rq", "redis"))


def run(ns: argparse.Namespace, err: TextIO) -> int:
    """Run the worker until it is stopped (or the queue is empty with ``--burst``)."""
    if not _distributed_installed():
        raise CliError(MISSING_EXTRA, EXIT_USAGE)
    from service.jobs.distributed.worker import main as worker_main

    return int(worker_main(list(ns.worker_args)))
