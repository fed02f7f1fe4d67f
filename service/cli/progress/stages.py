"""What ``smooth`` is doing, on stderr: a line per stage with the progress and an estimate.

The stages a run goes through (:data:`STAGES`) come from the use case (``reading``,
``writing``) and from the engine's progress events (:class:`service.core.ProgressEvent`: its
stage, and inside ``neighborhoods`` its ``step``). The percentage is the jobs' estimate
(:class:`service.jobs.progress.ProgressTracker`: stage-weighted, the search's share filled as
``|phi - tau| / tau`` comes down to the tolerance), so ``smooth`` and a job's
``GET /v1/jobs/{id}`` say the same; so is the time left from the search on. Before it, a
stage's share says little about time (the neighbourhoods of a large cloud can take longer than
the search), so the time left is the engine's own model of the input's size
(:meth:`StageDisplay.expect`, :func:`service.core.linalg.resources.estimate_resources`) less
the time spent since the input was read, when that model is known.

When the engine says nothing for a while a ticker thread repeats the current stage with its
clock: every :data:`TICK` seconds on a terminal (one line kept up to date) and with
``--progress json``, every :data:`LOG_TICK` seconds into a log.

``--progress text`` shows the stages whatever the input; the default (``auto``) shows them
for an input file of :data:`STAGES_FROM_BYTES` or more (a small run keeps its few lines: the
search and the summary). ``--progress json`` writes one JSON object per line
(:meth:`StageDisplay.record`); the summary comes as ``{"event": "summary", "text": ...}`` and
the report stays ``--report``'s. ``--quiet`` writes nothing and starts no thread.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import threading
import time
from typing import TYPE_CHECKING, Any, TextIO

from service.cli.progress.display import ProgressDisplay

if TYPE_CHECKING:
    from service.core.progress import ProgressEvent, ProgressModel

__all__ = ["LOG_TICK", "STAGES", "STAGES_FROM_BYTES", "TICK", "StageDisplay", "display_for"]

#: The stages of ``smooth`` in run order: the names a job's events and ``GET /v1/jobs/{id}``
#: give (:data:`service.core.progress.STAGES`, issue 41), less ``queued`` and ``done`` and the
#: ``laplacian`` the engine builds inside ``neighborhoods``. The engine's ``step`` inside
#: ``neighborhoods`` (``weights``, ``noise``) is shown as ``neighborhoods: weights``.
STAGES = ("reading", "neighborhoods", "analysis", "search", "postprocess", "writing")
#: Stages the display folds into the one before (no event of their own in a run).
_FOLDED = {"laplacian": "neighborhoods"}
#: Seconds between updates on a terminal and in JSON mode while a stage is silent.
TICK = 1.0
#: The same into a file or pipe (plain lines: a log is not flooded).
LOG_TICK = 10.0
#: ``--progress auto`` shows the stages from this input file size (about 30,000 points of
#: text XYZ; a smaller run takes about a second).
STAGES_FROM_BYTES = 1 << 20


def display_for(ns: argparse.Namespace, stream: TextIO, tolerance: float) -> StageDisplay:
    """The display ``--progress`` and ``--quiet`` ask for (``ns.input``: the one input file)."""
    mode = getattr(ns, "progress", "auto")
    if mode == "auto":
        try:
            big = ns.input != "-" and os.stat(ns.input).st_size >= STAGES_FROM_BYTES
        except (OSError, TypeError, ValueError):
            big = False
        mode = "text" if big else "search"
    return StageDisplay(stream, tolerance, enabled=not ns.quiet, stages=mode != "search",
                        json_lines=mode == "json")  # fmt: skip


def _eta(seconds: float | None) -> str:
    if seconds is None:
        return ""
    return f", ~{seconds:.0f} s left" if seconds >= 1 else ", <1 s left"


class StageDisplay(ProgressDisplay):
    """The progress callback of a local ``smooth`` run: stage lines, search lines, ticks.

    Parameters
    ----------
    stream : TextIO
        Where to write (stderr).
    tolerance : float
        The relative tolerance of the lambda search (the end of its progress).
    enabled : bool, optional
        ``False`` (``--quiet``) writes nothing and starts no thread.
    tty : bool or None, optional
        Terminal mode (one updating line); default ``stream.isatty()``.
    stages : bool, optional
        ``False``: only the search lines of :class:`ProgressDisplay` (no stages, no thread).
    json_lines : bool, optional
        ``--progress json``: one JSON object per line instead of text.
    tick : float or None, optional
        Seconds between updates of a silent stage (default :data:`TICK` on a terminal or in
        JSON mode, else :data:`LOG_TICK`).
    """

    def __init__(
        self,
        stream: TextIO,
        tolerance: float,
        *,
        enabled: bool = True,
        tty: bool | None = None,
        stages: bool = True,
        json_lines: bool = False,
        tick: float | None = None,
    ) -> None:
        super().__init__(stream, enabled=enabled, tty=False if json_lines else tty)
        self.stages = stages or json_lines
        self.json_lines = json_lines
        self.tolerance = tolerance
        self.interval = tick if tick is not None else (TICK if self.tty or json_lines else LOG_TICK)
        if self.stages:  # the jobs' package only when the stages are shown
            from service.jobs.progress import ProgressTracker

            self._tracker = ProgressTracker(tolerance=tolerance)
        self._t0 = time.perf_counter()
        self._lock = threading.RLock()
        self._stage: str | None = None
        self._base: str | None = None  # the stage of STAGES (without the step)
        self._stage_t0 = self._t0
        self._last_out = self._t0
        self._data: dict[str, Any] = {}
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._expected: tuple[float, float] | None = None  # (model seconds, clock at start)
        self._model: ProgressModel | None = None
        self._phases: list[tuple[str, float]] = []  # (phase, elapsed) entered so far

    def sized(self, n: int) -> None:
        """The input's point count: from now on the percent and the time left are the
        measured cost model's (:class:`service.core.progress.ProgressModel`, issue 41)."""
        from service.core.progress import ProgressModel

        with self._lock:
            self._model = ProgressModel(n)
            for phase, at in self._phases:
                self._model.enter(phase, at)

    def expect(self, seconds: float) -> None:
        """The engine's model of the run's time (from now on), for the estimate before the
        search."""
        self._expected = (float(seconds), time.perf_counter())

    def _percent(self, now: float) -> float:
        if self._model is not None:
            return round(self._model.percent(now - self._t0), 2)
        return float(self._data.get("percent") or 0.0)

    def _eta_seconds(self, now: float) -> float | None:
        if self._model is not None:
            return self._model.eta(now - self._t0)
        eta = self._data.get("eta_seconds")
        before = self._base in ("reading", "neighborhoods")
        if before and self._expected is not None:
            seconds, start = self._expected
            return max(seconds - (now - start), 0.0)
        return None if before else eta

    # -- events -----------------------------------------------------------------------------
    def stage(self, name: str) -> None:
        """A stage of the use case itself (``reading``, ``writing``)."""
        if not self.stages:
            self.finish()
            return
        from service.core.progress import ProgressEvent

        self(ProgressEvent(name))

    def __call__(self, event: ProgressEvent) -> None:
        """The ``progress`` callback of :func:`service.core.smooth` (and of the use case)."""
        if not self.stages:
            super().__call__(event)
            return
        if event.tau is not None:
            self.tau = event.tau
        base = _FOLDED.get(event.stage, event.stage)
        shown: str | None = f"{base}: {event.step}" if event.step else base
        if base not in STAGES:
            shown = None
        with self._lock:
            now = time.perf_counter()
            from service.core.progress import phase_of

            phase = phase_of(event.stage, event.step)
            if phase is not None:
                self._phases.append((phase, now - self._t0))
                if self._model is not None:
                    self._model.enter(phase, now - self._t0)
            timed = dataclasses.replace(event, elapsed=now - self._t0)  # reading included
            self._data = self._tracker.update(timed)
            if shown is not None and shown != self._stage:
                self.finish()  # a terminal keeps the stage just ended on its own line
                self._stage, self._stage_t0 = shown, now
                self._base = base
                self._out("stage", now)
            if event.lam is not None and event.phi is not None:
                self.calls += 1
                self.last_iteration = max(self.last_iteration, event.iteration)
                if self.json_lines or not self.repeats(event.lam, event.phi):  # data: every one
                    self._out("iteration", now)
        self._start_ticker()

    # -- output -----------------------------------------------------------------------------
    def record(self, kind: str, now: float) -> dict[str, Any]:
        """The JSON object of one line: ``event`` (``stage``, ``iteration``, ``tick``), the
        stage shown and its number, the clocks and the jobs' progress numbers."""
        d = self._data
        stage = self._base or ""
        step = (self._stage or "").partition(": ")[2] or None
        return {
            "event": kind,
            "stage": stage,
            "step": step,
            "index": STAGES.index(stage) + 1 if stage in STAGES else None,
            "stages": len(STAGES),
            "elapsed_seconds": round(now - self._t0, 3),
            "stage_seconds": round(now - self._stage_t0, 3),
            "percent": self._percent(now),
            "eta_seconds": None if (eta := self._eta_seconds(now)) is None else round(eta, 3),
            "iteration": d.get("iteration", 0),
            "lambda": d.get("lambda") if kind == "iteration" else None,
            "phi": d.get("phi") if kind == "iteration" else None,
            "tau": d.get("tau"),
            "relative_error": d.get("relative_error") if kind == "iteration" else None,
            **{k: d[k] for k in ("tiles_done", "tiles_total", "points_per_second") if k in d},
        }

    def text(self, kind: str, now: float) -> str:
        """The text of one line (without line ending)."""
        d = self._data
        where = f"[{STAGES.index(self._base) + 1}/{len(STAGES)}] " if self._base in STAGES else ""
        eta = _eta(self._eta_seconds(now))
        clock = f"{now - self._t0:.1f} s, {self._percent(now):.0f} %{eta}"
        if kind == "iteration" and d.get("lambda") is not None and d.get("phi") is not None:
            line = self.line(int(d.get("iteration", 0)), float(d["lambda"]), float(d["phi"]))
            return f"{line}  ({clock})"
        stage_clock = f" {now - self._stage_t0:.1f} s" if kind == "tick" else ""
        if d.get("tiles_total"):  # a tiled run (issue 43)
            pps = d.get("points_per_second")
            rate = f", {pps:.0f} points/s" if pps else ""
            stage_clock += f", tile {d.get('tiles_done', 0)}/{d['tiles_total']}{rate}"
        return f"geosmooth: {where}{self._stage}{stage_clock}  ({clock})"

    def _out(self, kind: str, now: float) -> None:
        self._last_out = now
        if not self.enabled:
            return
        if self.json_lines:
            self.stream.write(json.dumps(self.record(kind, now)) + "\n")
            self.stream.flush()
            return
        self.put(self.text(kind, now))

    def note(self, text: str) -> None:
        """A line of its own (the summary): ``{"event": "summary", "text": ...}`` in JSON mode."""
        self.close()  # the run is over
        if self.enabled and self.json_lines:
            self.stream.write(json.dumps({"event": "summary", "text": text}) + "\n")
            self.stream.flush()
            return
        super().note(text)

    # -- ticker -----------------------------------------------------------------------------
    def _start_ticker(self) -> None:
        if self._thread is not None or not (self.enabled and self.stages) or self._stop.is_set():
            return
        self._thread = threading.Thread(target=self._tick, name="geosmooth-progress", daemon=True)
        self._thread.start()

    def _tick(self) -> None:
        while not self._stop.wait(min(self.interval, 0.25)):
            with self._lock:
                now = time.perf_counter()
                if self._stage is not None and now - self._last_out >= self.interval:
                    self._out("tick", now)

    def close(self) -> None:
        """Stop the ticker and end the terminal line (the run is over or failed)."""
        self._stop.set()
        thread, self._thread = self._thread, None
        if thread is not None:
            thread.join()
        self.finish()

