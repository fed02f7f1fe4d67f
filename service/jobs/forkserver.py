"""The multiprocessing forkserver of a server process, prepared once for every process it forks.

Both backends' API processes fork request processes from it (uploads parsed and checked at
submit, :mod:`service.api.intake.isolation`); the embedded backend forks its job processes from
it too. :func:`prepare_forkserver` sets the BLAS/OpenMP thread cap the forkserver applies
(``GEOSMOOTH_THREADS_PER_JOB``, read by :mod:`service.jobs.preload`) and preloads the engine.

Without it (the RQ backend's API before issue 42) the forkserver started on the first upload
with neither: OpenBLAS loaded in each request process under its 1 GiB address-space limit with
one thread per core, and the phi(0) check's factorization of a 48K-vertex mesh looped in
``mmap`` until the CPU limit (413 ``ingest-time-limit`` after 108 s; 0.8 s embedded).
"""

from __future__ import annotations

import ast
import importlib
import logging
import multiprocessing
import multiprocessing.forkserver
import os
import sys
from collections.abc import Iterable
from pathlib import Path

__all__ = ["PRELOAD", "main_module_imports", "prepare_forkserver"]

log = logging.getLogger("geosmooth.jobs")

#: What every forkserver preloads: the engine, warmed up (:mod:`service.jobs.preload`).
PRELOAD = ("service.jobs.runner", "service.jobs.preload")


def main_module_imports() -> list[str]:
    """Modules the ``__main__`` module imports at its top level (and this process has loaded).

    multiprocessing re-runs the main module in every spawn/forkserver child (as
    ``__mp_main__``). Preloading its imports in the forkserver makes that re-run cheap: with
    ``python -m uvicorn``/``geosmooth serve``-style mains importing FastAPI it saves ~150 ms
    per job.
    """
    path = getattr(sys.modules.get("__main__"), "__file__", None)
    if not path:
        return []
    try:
        tree = ast.parse(Path(path).read_bytes())
    except (OSError, SyntaxError, ValueError):
        return []
    names: list[str] = []
    for node in tree.body:
        if isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.append(node.module)
    return [n for n in dict.fromkeys(names) if n in sys.modules and n != "__future__"]


def prepare_forkserver(threads: int, modules: Iterable[str] = ()) -> list[str]:
    """Start the forkserver with the thread cap ``threads`` and the engine preloaded (with
    ``modules`` and the main module's imports); the modules preloaded.

    Only what imports cleanly here is preloaded (a broken import must not kill the server).
    Called before the forkserver first runs (a running one keeps what it had).
    """
    os.environ["GEOSMOOTH_THREADS_PER_JOB"] = str(threads)
    preload = []
    for name in dict.fromkeys((*modules, *PRELOAD, *main_module_imports())):
        try:
            importlib.import_module(name)
        except Exception as exc:
            log.warning("not preloading %s in the forkserver: %s", name, exc)
        else:
            preload.append(name)
    multiprocessing.get_context("forkserver").set_forkserver_preload(preload)
    multiprocessing.forkserver.ensure_running()
    return preload
