"""Entry point of the embedded queue's worker process: one process runs one job run, then exits.

The process

1. dies with its server, three ways: a watchdog thread waits on multiprocessing's parent
   sentinel (a pipe the server holds: it reads EOF the moment the server dies, however it
   dies) and SIGKILLs the process; ``prctl(PR_SET_PDEATHSIG, SIGKILL)`` on Linux makes the
   kernel do the same when the parent dies, even while the job holds the GIL in C code; and the
   copy of the forkserver's "server alive" pipe that forkserver children inherit is closed, so
   the forkserver (the parent under the forkserver start method) exits with the server and
   does not wait for its children to finish first;
2. leaves the server's session (``setsid``) and ignores SIGINT, so a Ctrl-C or a terminal hangup
   aimed at the server does not kill the job mid-run (the server's ``stop()`` requeues it);
3. checks that its run still holds the job (``owner`` + ``attempt``); every progress write and the
   final write are conditional on that too, so a stale run (an orphan on a system without
   ``PDEATHSIG``, a run whose server was presumed dead) can never overwrite a newer run;
4. runs the job function (:func:`service.jobs.execute.run_function`, with its tiles on local
   processes) and records ``succeeded`` (report) or ``failed`` (problem).

If it dies without recording (segfault, ``os._exit``, SIGKILL), the server records the crash.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import multiprocessing.connection
import os
import signal
import sqlite3
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from service.jobs import problems
from service.jobs.embedded.store import JobStore
from service.jobs.errors import storage_error
from service.jobs.execute import RunOptions, run_function, write_report
from service.jobs.files import JobFiles
from service.jobs.limits import limit_memory, set_parent_death_signal
from service.jobs.progress import final_progress
from service.jobs.runner import RunLost
from service.jobs.tiles.local import local_tile_map

#: A run that failed for want of space goes back to the queue (not counted as a try) and is
#: tried again after this many seconds, until space comes back (the job is not failed).
STORAGE_RETRY_SECONDS = float(os.environ.get("GEOSMOOTH_STORAGE_RETRY_SECONDS") or 30.0)

#: Exit status of a run that could not record its outcome (the store's disk full or failing):
#: the server requeues it (EX_TEMPFAIL).
EXIT_UNRECORDED = 75

__all__ = ["EXIT_UNRECORDED", "RunSpec", "main"]


@dataclass(frozen=True)
class RunSpec:
    """What a worker process needs (pickled to it; no arrays, only names and paths)."""

    job_id: str
    fmt: str
    attempt: int
    owner: str
    data_dir: str
    db_path: str
    runner: str
    server_pid: int
    progress_interval: float = 0.2
    memory_limit: int | None = None


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # pragma: no cover - exists, owned by someone else
        return True
    return True


def _release_forkserver() -> None:
    """Close this process's copy of the forkserver's liveness pipe (forkserver children only).

    The forkserver exits when every write end of that pipe is closed; each forked child gets
    one, so without this the forkserver (and, with PDEATHSIG, its children) would outlive a
    killed server for as long as any job runs.
    """
    try:
        from multiprocessing import forkserver

        server = forkserver._forkserver  # type: ignore[attr-defined]
        fd = server._forkserver_alive_fd  # type: ignore[attr-defined]
    except AttributeError:  # pragma: no cover - other Python versions
        return
    if fd is not None:  # only set in children of a forkserver
        with contextlib.suppress(OSError):
            os.close(fd)
        server._forkserver_alive_fd = None  # type: ignore[attr-defined]


def _watch_parent() -> None:
    """SIGKILL this process as soon as the process that started it is gone."""
    parent = multiprocessing.parent_process()
    if parent is None or parent.sentinel is None:  # pragma: no cover - not a multiprocessing child
        return
    sentinel = parent.sentinel

    def watch() -> None:
        multiprocessing.connection.wait([sentinel])
        os.kill(os.getpid(), signal.SIGKILL)

    threading.Thread(target=watch, name="geosmooth-parent-watch", daemon=True).start()


def main(spec: RunSpec) -> None:
    """Run one job run and record its outcome (the target of the worker process)."""
    set_parent_death_signal()
    _release_forkserver()
    _watch_parent()
    if not _alive(spec.server_pid):  # the server died before the signals were armed
        os._exit(0)
    with contextlib.suppress(OSError):  # already a session leader
        os.setsid()
    signal.signal(signal.SIGINT, signal.SIG_IGN)

    store = JobStore(Path(spec.db_path), create=False)
    try:
        _run(spec, store)
    finally:
        store.close()


def _run(spec: RunSpec, store: JobStore) -> None:
    if not store.owns(spec.job_id, spec.owner, spec.attempt):
        return
    files = JobFiles(Path(spec.data_dir))

    def report_progress(progress: dict[str, Any]) -> bool:
        try:
            return store.progress(spec.job_id, spec.owner, spec.attempt, progress)
        except Exception as exc:  # progress is advice: a full disk must not end the run here
            if storage_error(exc) is None:
                raise
            return True  # the outcome's write (with the reserve) or the server settles it

    started = time.perf_counter()
    options = RunOptions(spec.runner, spec.memory_limit, spec.progress_interval, local_tile_map)
    try:
        rec = store.get(spec.job_id)
        if rec is None:
            return
        limit_memory(spec.memory_limit)  # threads: set in the forkserver's environment
        ctx, report = run_function(rec, files.dir(spec.job_id), files.input(spec.job_id, spec.fmt),
                                   report_progress, options)  # fmt: skip
        elapsed = time.perf_counter() - started
        if not store.owns(spec.job_id, spec.owner, spec.attempt):
            return
        write_report(ctx, report)
        store.succeed(spec.job_id, spec.owner, spec.attempt, final_progress(report, elapsed),
                      elapsed)  # fmt: skip
    except RunLost:
        return
    except BaseException as exc:
        _record_failure(spec, store, exc)


def _record_failure(spec: RunSpec, store: JobStore, exc: BaseException) -> None:
    """Fail the run with ``exc``'s problem, or requeue it when the disk is full; if even that
    cannot be written (the store's disk is full or failing), exit with
    :data:`EXIT_UNRECORDED`: the server settles the run (requeued, retried until recorded)."""
    problem = problems.from_exception(exc)
    try:
        if problem["code"] == "storage-full":  # retried (not failed) until space is back
            again = time.time() + STORAGE_RETRY_SECONDS
            if store.requeue(spec.job_id, spec.owner, spec.attempt, False, again):
                return
        store.fail(spec.job_id, spec.owner, spec.attempt, problem)
    except Exception as failed:
        if storage_error(failed) is None and not isinstance(failed, sqlite3.Error):
            raise
        os._exit(EXIT_UNRECORDED)
