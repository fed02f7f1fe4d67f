"""``geosmooth worker``: an RQ worker of the distributed backend (``GEOSMOOTH_QUEUE=rq``).

The worker itself is :func:`service.jobs.distributed.worker.main`; this command forwards its options
(``--burst``, ``--max-jobs``, ``--name``, ``--log-level``) and reads the same ``GEOSMOOTH_*``
settings as ``geosmooth serve``.
"""

from __future__ import annotations

import argparse
from typing import TextIO

__all__ = ["run"]


def run(ns: argparse.Namespace, err: TextIO) -> int:
    """Run the worker until it is stopped (or the queue is empty with ``--burst``)."""
    from service.jobs.distributed.worker import main as worker_main

    return int(worker_main(list(ns.worker_args)))
