"""The lambda-search progress line of ``smooth`` and ``submit``.

It writes to a text stream (stderr in the CLI) so that stdout stays free for ``-o -``, and
imports neither numpy nor the engine: the line shows ``(iteration, lambda, phi, tau)`` from a
local progress event or a remote job alike.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, TextIO

if TYPE_CHECKING:
    from service.core.progress import ProgressEvent

__all__ = ["ProgressDisplay", "fmt_g"]


def fmt_g(value: float | None, digits: int = 4) -> str:
    """Format a float compactly in scientific notation (``-`` for ``None``)."""
    if value is None:
        return "-"
    return f"{value:.{digits}e}"


class ProgressDisplay:
    """Progress of the lambda search, shown while :func:`service.core.pipeline` iterates.

    An instance is the ``progress(event)`` callback of ``smooth()``; it shows the search
    iterations (stage ``search``) with the engine's resolved ``tau``. On a
    terminal it keeps one line up to date with carriage returns; on anything else (a pipe, a
    log file, a CI job) it writes one plain line per iteration.

    Parameters
    ----------
    stream : TextIO
        Where to write (the CLI passes ``sys.stderr``).
    tau : float or None, optional
        The smoothing factor to compare with until an event carries the engine's own.
    enabled : bool, optional
        ``False`` (``--quiet``) writes nothing at all.
    tty : bool or None, optional
        Force terminal (``True``) or plain-line (``False``) mode; by default
        ``stream.isatty()`` decides.
    """

    def __init__(
        self,
        stream: TextIO,
        tau: float | None = None,
        *,
        enabled: bool = True,
        tty: bool | None = None,
    ) -> None:
        self.stream = stream
        self.tau = tau
        self.enabled = enabled
        if tty is None:
            isatty = getattr(stream, "isatty", None)
            tty = bool(isatty()) if callable(isatty) else False
        self.tty = tty
        self.calls = 0
        self.last_iteration = 0
        self._width = 0
        self._shown: tuple[str, str] | None = None
        self.tolerance: float | None = None  # the search's, when known
        self._converged = False

    def repeats(self, lam: float, phi: float) -> bool:
        """Whether the line of ``(lam, phi)`` would tell nothing new: it reads as the line
        shown last (same lambda and phi to the digits shown), or the search had converged
        (relative error within the tolerance) and still has (the engine refining lambda).
        Such lines are not printed, so a converged search prints no further iterations
        (issue 41); the summary still counts every evaluation."""
        shown = (fmt_g(lam), fmt_g(phi))
        rel = None if not self.tau else abs(phi - self.tau) / self.tau
        converged = rel is not None and self.tolerance is not None and rel <= self.tolerance
        if self._shown == shown or (converged and self._converged):
            return True
        self._shown, self._converged = shown, converged
        return False

    def line(self, iteration: int, lam: float, phi: float) -> str:
        """The text shown for one iteration (without line ending).

        Parameters
        ----------
        iteration : int
            1-based lambda iteration.
        lam, phi : float
            The lambda just tried and the deviation ``phi(lam)`` it gives (eq. 15).

        Returns
        -------
        str
        """
        text = f"geosmooth: iteration {iteration:>2}  lambda={fmt_g(lam)}  phi={fmt_g(phi)}"
        if self.tau is not None:
            rel = abs(phi - self.tau) / self.tau
            text += f"  tau={fmt_g(self.tau)}  rel.error={fmt_g(rel, 2)}"
        return text

    def __call__(self, event: ProgressEvent) -> None:
        """The ``progress`` callback of :func:`service.core.smooth`."""
        if event.tau is not None:
            self.tau = event.tau
        if event.lam is None or event.phi is None:
            return
        self.show(event.iteration, event.lam, event.phi)

    def show(self, iteration: int, lam: float, phi: float, tau: float | None = None) -> None:
        """Show one lambda iteration (``tau``: the target, when newly known)."""
        if tau is not None:
            self.tau = tau
        self.calls += 1
        self.last_iteration = max(self.last_iteration, iteration)
        if not self.enabled or self.repeats(lam, phi):
            return
        self.put(self.line(iteration, lam, phi))

    def put(self, text: str) -> None:
        """``text`` as the updating line: rewritten in place on a terminal, a line of its own
        in a log."""
        if self.tty:
            pad = max(0, self._width - len(text))
            self.stream.write("\r" + text + " " * pad)
            self._width = len(text)
        else:
            self.stream.write(text + "\n")
        self.stream.flush()

    def note(self, text: str) -> None:
        """A line of its own (e.g. a job's status), below the updating line."""
        if not self.enabled:
            return
        self.finish()
        self.stream.write(text + "\n")
        self.stream.flush()

    def finish(self) -> None:
        """End the updating terminal line (call once the search is over or interrupted)."""
        if self.enabled and self.tty and self._width:
            self.stream.write("\n")
            self.stream.flush()
        self._width = 0

    def stage(self, name: str) -> None:
        """A stage of the use case (``reading``, ``writing``): ends the search line here
        (:class:`service.cli.progress.stages.StageDisplay` shows it)."""
        self.finish()

    def expect(self, seconds: float) -> None:
        """The engine's model of the run's time (used by the stage lines only)."""

    def sized(self, n: int) -> None:
        """The input's point count, once read (the stage lines' progress model)."""

    def close(self) -> None:
        """The run is over (or failed): end the terminal line."""
        self.finish()
