"""Worker slots: threads in the server that each run one job at a time in a child process.

Each slot thread claims the oldest queued job, starts a worker process for it
(:func:`service.jobs.embedded.child.main`), then watches it until it exits: it renews the run's
lease, enforces the time limit, and kills the process (SIGTERM to its process group, SIGKILL after a
grace period) on cancel, timeout, stop or when the run lost its job. Only the slot thread touches
its process object; other threads ask for a kill and wait for the slot to settle.

Start method: ``forkserver`` on Linux (the forkserver preloads numpy/scipy/the engine once, so a
job starts in a few milliseconds instead of the ~300 ms of a fresh ``spawn`` interpreter, and
forks from a single-threaded process, which is safe next to uvicorn's threads); ``spawn``
elsewhere. Both can be chosen explicitly.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import multiprocessing.context
import multiprocessing.forkserver
import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from service.jobs import problems
from service.jobs.embedded import child
from service.jobs.embedded.store import Claim, JobStore
from service.jobs.forkserver import prepare_forkserver

if TYPE_CHECKING:
    from service.jobs.config import LocalConfig

__all__ = ["WorkerPool", "default_start_method"]

log = logging.getLogger("geosmooth.jobs")

_TICK = 0.05
#: Signals by which a job process kills itself (its own bug or bad input): the job fails. Any
#: other signal came from outside (the OOM killer's SIGKILL, a stop of the whole service): the
#: run was interrupted and is retried like a server death.
_CRASH_SIGNALS = frozenset(
    -int(s) for s in (signal.SIGSEGV, signal.SIGBUS, signal.SIGFPE, signal.SIGILL, signal.SIGABRT,
                      signal.SIGSYS, signal.SIGTRAP)
)  # fmt: skip
_MAX_BACKOFF = 300.0
#: Seconds a slot keeps trying to record a run's outcome before leaving it to the sweep.
SETTLE_SECONDS = 50.0


def default_start_method() -> str:
    """``forkserver`` where available (Linux), else ``spawn``."""
    methods = multiprocessing.get_all_start_methods()
    return "forkserver" if sys.platform.startswith("linux") and "forkserver" in methods else "spawn"


@dataclass
class _Run:
    claim: Claim
    process: multiprocessing.process.BaseProcess
    deadline: float | None
    reason: str | None = None  # why the slot killed it: cancelled, timeout, stop, lost
    done: threading.Event = field(default_factory=threading.Event)


class WorkerPool:
    """A fixed number of slots running jobs of one store.

    Parameters
    ----------
    config : LocalConfig
        Slots (``workers``), job function (``runner``), ``job_timeout``, ``lease``,
        ``kill_grace``, ``poll_interval``, ``start_method``, ``progress_interval``,
        ``retry_backoff``, ``memory_limit`` (``RLIMIT_AS`` of a job process) and ``threads``
        (BLAS/OpenMP threads per job process, set in the environment they start with).
    store : JobStore
        Job metadata.
    owner : str
        Identity of this server instance in the store's ``owner`` column.
    on_settled : callable, optional
        Called with the job id after each run ends (for metrics and webhooks).
    """

    def __init__(
        self,
        config: LocalConfig,
        store: JobStore,
        owner: str,
        on_settled: Callable[[str], None] | None = None,
    ) -> None:
        if config.workers < 1:
            raise ValueError("workers must be >= 1")
        self.config = config
        self.store = store
        self.owner = owner
        self.on_settled = on_settled
        self.start_method = config.start_method or default_start_method()
        self._ctx: multiprocessing.context.BaseContext | None = None
        self._threads: list[threading.Thread] = []
        self._runs: dict[str, _Run] = {}
        self._lock = threading.Lock()
        self._cond = threading.Condition()
        self._generation = 0
        self._stopping = threading.Event()

    @property
    def runner(self) -> str:
        """The job function, ``"module:function"``."""
        return self.config.runner

    # -- life cycle ----------------------------------------------------------------------
    def start(self) -> None:
        """Prepare the process context (start the forkserver) and start the slot threads."""
        self._ctx = multiprocessing.get_context(self.start_method)
        # read by service.jobs.preload in the forkserver: the limit every job process inherits
        os.environ["GEOSMOOTH_THREADS_PER_JOB"] = str(self.config.threads)
        if self.start_method == "forkserver":
            modules = ("service.jobs.embedded.child", self.config.runner.partition(":")[0])
            prepare_forkserver(self.config.threads, modules)
        self._stopping.clear()
        self._threads = [
            threading.Thread(target=self._slot, name=f"geosmooth-slot-{i}", daemon=True)
            for i in range(self.config.workers)
        ]
        for t in self._threads:
            t.start()

    def stop(self, timeout: float = 30.0) -> None:
        """Stop the slots; running jobs are killed and put back in the queue (not as a try)."""
        self._stopping.set()
        self.notify()
        deadline = time.monotonic() + timeout
        for t in self._threads:
            t.join(max(0.0, deadline - time.monotonic()))
        self._threads = []

    def notify(self) -> None:
        """Wake idle slots (a job was submitted)."""
        with self._cond:
            self._generation += 1
            self._cond.notify_all()

    def busy(self) -> int:
        """Slots running a job now."""
        with self._lock:
            return len(self._runs)

    def backoff(self, attempts: int) -> float:
        """Seconds an interrupted job waits before its next run, after ``attempts`` runs."""
        return min(_MAX_BACKOFF, self.config.retry_backoff * 2 ** max(0, attempts - 1))

    def kill(self, job_id: str, reason: str = "cancelled", wait: float | None = None) -> bool:
        """Ask the slot running ``job_id`` to kill its process; wait until it has settled.

        Returns ``False`` if the job is not running in this pool.
        """
        with self._lock:
            run = self._runs.get(job_id)
            if run is None:
                return False
            if run.reason is None:
                run.reason = reason
        run.done.wait(self.config.kill_grace + 5.0 if wait is None else wait)
        return True

    # -- slots ---------------------------------------------------------------------------
    def _slot(self) -> None:
        while not self._stopping.is_set():
            with self._cond:
                generation = self._generation
            try:
                claim = self.store.claim(self.owner, self.config.lease)
            except Exception:
                log.exception("could not claim a job")
                claim = None
            if claim is None:
                with self._cond:
                    if self._generation == generation and not self._stopping.is_set():
                        self._cond.wait(self.config.poll_interval)
                continue
            try:
                self._execute(claim)
            except Exception:
                log.exception("slot failed running job %s", claim.job_id)

    def _execute(self, claim: Claim) -> None:
        assert self._ctx is not None
        spec = child.RunSpec(
            job_id=claim.job_id,
            fmt=claim.fmt,
            attempt=claim.attempt,
            owner=self.owner,
            data_dir=str(self.config.data_dir),
            db_path=str(self.store.path),
            runner=self.config.runner,
            server_pid=os.getpid(),
            progress_interval=self.config.progress_interval,
            memory_limit=self.config.memory_limit,
        )
        process = self._ctx.Process(  # type: ignore[attr-defined]
            target=child.main, args=(spec,), name=f"geosmooth-job-{claim.job_id[:8]}", daemon=True
        )
        timeout = self.config.job_timeout
        deadline = None if not timeout else time.monotonic() + timeout
        run = _Run(claim, process, deadline)
        try:
            process.start()
        except Exception as exc:  # e.g. out of processes or file descriptors: retry later
            log.exception("could not start a worker process for job %s", claim.job_id)
            rec = self.store.get(claim.job_id)
            if rec is not None and rec.attempts >= rec.max_attempts:
                self.store.fail(
                    claim.job_id, self.owner, claim.attempt, problems.from_exception(exc)
                )
            else:
                self.store.requeue(claim.job_id, self.owner, claim.attempt, True,
                                   time.time() + self.backoff(claim.attempt))  # fmt: skip
                self._stopping.wait(1.0)
            return
        with self._lock:
            self._runs[claim.job_id] = run
        try:
            with contextlib.suppress(Exception):  # advice only (a full disk: the run goes on)
                self.store.set_pid(claim.job_id, self.owner, claim.attempt, process.pid or 0)
            self._watch(run)
            self._settle_until_recorded(run)
        finally:
            with self._lock:
                self._runs.pop(claim.job_id, None)
            run.done.set()
            with contextlib.suppress(Exception):
                process.close()
        if self.on_settled is not None:
            try:
                self.on_settled(claim.job_id)
            except Exception:
                log.exception("on_settled failed for job %s", claim.job_id)

    def _watch(self, run: _Run) -> None:
        claim, process = run.claim, run.process
        run_of = (claim.job_id, self.owner, claim.attempt)
        now = time.monotonic()
        next_check = now + self.config.poll_interval
        next_renew = now + self.config.lease / 3
        while True:
            process.join(_TICK)
            if process.exitcode is not None:
                return
            now = time.monotonic()
            reason = run.reason
            if reason is None and self._stopping.is_set():
                reason = "stop"
            if reason is None and run.deadline is not None and now >= run.deadline:
                reason = "timeout"
            if reason is None and now >= next_renew:
                next_renew = now + self.config.lease / 3
                if self._lost(lambda: self.store.renew(*run_of, self.config.lease), claim.job_id):
                    reason = "lost"
            elif reason is None and now >= next_check:
                next_check = now + self.config.poll_interval
                if self._lost(lambda: self.store.owns(*run_of), claim.job_id):
                    reason = "lost"
            if reason is not None:
                with self._lock:
                    run.reason = run.reason or reason
                self._terminate(process)
                return

    @staticmethod
    def _lost(holds: Callable[[], bool], job_id: str) -> bool:
        """Whether the store says the run lost its job (a store that cannot be read or written
        now, e.g. a full disk, says nothing: the run goes on)."""
        try:
            return not holds()
        except Exception as exc:
            log.warning("job %s: lease not renewed: %s", job_id, exc)
            return False

    def _terminate(self, process: multiprocessing.process.BaseProcess) -> None:
        pid = process.pid
        assert pid is not None
        for sig, wait in ((signal.SIGTERM, self.config.kill_grace), (signal.SIGKILL, None)):
            try:  # the worker leads its own process group: take any children of the job too
                os.killpg(pid, sig)
            except (ProcessLookupError, PermissionError):
                with contextlib.suppress(ProcessLookupError):
                    os.kill(pid, sig)
            process.join(wait)
            if process.exitcode is not None:
                return

    def running_ids(self) -> set[str]:
        """Jobs a slot of this pool runs (or settles) now."""
        with self._lock:
            return set(self._runs)

    def _settle_until_recorded(self, run: _Run) -> None:
        """:meth:`_settle`, tried again every second for :data:`SETTLE_SECONDS` while the store
        cannot be written (a full or failing disk: the reserve may come back, space may be
        freed); then the run is left to the sweep, which requeues a run no slot holds once its
        lease expired (:meth:`~service.jobs.embedded.maintenance.Maintenance.recover`)."""
        deadline = time.monotonic() + SETTLE_SECONDS
        while True:
            try:
                self._settle(run)
                return
            except Exception as exc:
                if time.monotonic() >= deadline or self._stopping.is_set():
                    log.error("job %s: outcome not recorded (%s); left to the sweep",
                              run.claim.job_id, exc)  # fmt: skip
                    return
                log.warning("job %s: outcome not recorded yet: %s", run.claim.job_id, exc)
                self._stopping.wait(1.0)

    def _settle(self, run: _Run) -> None:
        claim, store = run.claim, self.store
        job_id, attempt, owner = claim.job_id, claim.attempt, self.owner
        if run.reason == "timeout":
            assert self.config.job_timeout is not None
            store.fail(job_id, owner, attempt, problems.timed_out(self.config.job_timeout))
        elif run.reason == "stop":
            store.requeue(job_id, owner, attempt, count_attempt=False)
        elif run.reason is None and store.owns(job_id, owner, attempt):
            # the process ended without recording an outcome
            code = run.process.exitcode
            if code == child.EXIT_UNRECORDED:  # its store write failed (disk full, I/O error)
                store.requeue(job_id, owner, attempt, False,
                              time.time() + child.STORAGE_RETRY_SECONDS)  # fmt: skip
            elif code is not None and code < 0 and code not in _CRASH_SIGNALS:
                self._interrupted(job_id, attempt, code)  # e.g. the OOM killer's SIGKILL
            else:
                store.fail(job_id, owner, attempt, problems.crashed(code))
        # "cancelled" and "lost": the row was already changed by whoever took the job away

    def _interrupted(self, job_id: str, attempt: int, code: int) -> None:
        """A run killed from outside: requeued (after the backoff) or, out of attempts, failed."""
        rec = self.store.get(job_id)
        if rec is not None and rec.attempts >= rec.max_attempts:
            problem = problems.attempts_exhausted(rec.attempts, problems.crashed(code)["detail"])
            self.store.fail(job_id, self.owner, attempt, problem)
        else:
            log.warning("job %s: worker killed (exit %s), requeued", job_id, code)
            self.store.requeue(job_id, self.owner, attempt, True,
                               time.time() + self.backoff(attempt))  # fmt: skip
