"""Time in the tests: no bound that a busy machine breaks (issue 34).

Two kinds of time appear in the tests, and neither may fail because the machine is loaded:

* **hang guards** (wait until a job finishes, a process is gone, a file appears): they pass
  as soon as the condition holds, so a long guard costs nothing when things work.
  :func:`patience` stretches a nominal guard by :data:`HANG_FACTOR` and by the current load;
* **latency bounds** (``/healthz`` answers quickly during a flood, a shutdown deadline holds):
  a loaded machine makes everything slower by about the number of runnable tasks per core.
  :class:`Slowdown` measures that factor *during the test* (a small probe thread that times a
  fixed bit of CPU work against the wall clock), and a bound is stated per unit of it:
  ``latency < 1.0 * slowdown.factor``. On a quiet machine the factor is about 1 and the bound
  is the nominal one; at load 15 on 2 cores it is about 7.

CPU-bound speed checks of one process (a reader is fast) measure ``time.process_time()``
instead of the wall clock: CPU time does not grow with the load.
"""

from __future__ import annotations

import os
import threading
import time

__all__ = ["HANG_FACTOR", "Slowdown", "load_factor", "patience"]

#: How much longer than its nominal value every hang guard waits
#: (``GEOSMOOTH_TEST_HANG_FACTOR``, default 4).
HANG_FACTOR = float(os.environ.get("GEOSMOOTH_TEST_HANG_FACTOR", "") or 4.0)


def load_factor() -> float:
    """Runnable tasks per core over the last minute, at least 1 (``os.getloadavg``)."""
    try:
        load = os.getloadavg()[0]
    except OSError:  # pragma: no cover - not on Linux
        return 1.0
    return max(1.0, load / (os.cpu_count() or 1))


def patience(seconds: float) -> float:
    """A hang guard of nominally ``seconds``, stretched for a slow or busy machine."""
    return seconds * HANG_FACTOR * load_factor()


def _spin(n: int) -> int:
    total = 0
    for i in range(n):
        total += i * i
    return total


class Slowdown:
    """How much slower CPU work runs now than on an idle core, measured while the block runs.

    A daemon thread does ``work`` loop iterations (~10 ms of CPU here: a few scheduler slices,
    so that waiting for a core shows) every ``every`` seconds and records wall time over its
    own CPU time (``time.thread_time``): about 1 on a free core, about the runnable tasks per
    core on a busy machine (the GIL of this process counts too). ``factor`` is the largest of
    the median sample, the load average's :func:`load_factor` and 1, so one stall of the probe
    itself does not inflate it.

    Use::

        with Slowdown() as slow:
            ...  # the loaded part of the test
        assert latency < 1.0 * slow.factor
    """

    def __init__(self, every: float = 0.2, work: int = 200_000) -> None:
        self.every, self.work = every, work
        self.samples: list[float] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True, name="slowdown-probe")

    def _run(self) -> None:
        while not self._stop.is_set():
            wall, cpu = time.perf_counter(), time.thread_time()
            _spin(self.work)
            cpu = time.thread_time() - cpu
            wall = time.perf_counter() - wall
            if cpu > 0:
                self.samples.append(wall / cpu)
            self._stop.wait(self.every)

    def __enter__(self) -> Slowdown:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(10)

    @property
    def factor(self) -> float:
        """The slowdown seen so far (at least 1)."""
        samples = sorted(self.samples)
        median = samples[len(samples) // 2] if samples else 1.0
        return max(1.0, median, load_factor())

    def __repr__(self) -> str:
        return f"Slowdown(factor={self.factor:.2f}, samples={len(self.samples)})"
