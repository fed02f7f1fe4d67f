"""``geosmooth submit INPUT --server URL -o OUTPUT``: smooth on a geosmooth service.

Command-line code on top of the client library (:mod:`geosmooth_client`): the library uploads,
follows the job and cancels it on Ctrl-C; this module checks the options first, shows the
job's progress with the same line as ``smooth``, writes the result and the report with the same
writer, and turns the library's typed errors into the documented exit statuses.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from service.cli.errors import CliError, os_reason
from service.cli.output import check_writable, output_format, write_json_report, write_output
from service.cli.params import params_from_args
from service.cli.progress import ProgressDisplay, show_summary
from service.exit_codes import (
    EXIT_CANCELLED,
    EXIT_INPUT,
    EXIT_INTERRUPTED,
    EXIT_JOB_FAILED,
    EXIT_OK,
    EXIT_REJECTED,
    EXIT_SERVER,
    EXIT_SHAPE,
    EXIT_UNREACHABLE,
)

if TYPE_CHECKING:
    from geosmooth_client import Job

__all__ = ["JobProgress", "run"]


class JobProgress:
    """The client's progress callback: status lines, then the lambda iterations.

    Parameters
    ----------
    display : ProgressDisplay
        The progress line shared with ``smooth``.
    """

    def __init__(self, display: ProgressDisplay) -> None:
        self.display = display
        self.status: str | None = None

    def __call__(self, job: Job) -> None:
        if job.status != self.status and job.status in ("queued", "running"):
            self.display.note(f"geosmooth: job {job.id} {job.status}")
        self.status = job.status
        p = job.progress
        if job.status != "running" or p is None or p.lam is None or p.phi is None:
            return
        if p.iteration is not None and p.iteration > self.display.last_iteration:
            self.display.show(p.iteration, p.lam, p.phi, p.tau)

    def catch_up(self, report: Mapping[str, Any]) -> None:
        """Show the iterations the job went through between two looks at it (its history)."""
        tau = report.get("tau")
        for number, entry in enumerate(report.get("history") or [], start=1):
            if number > self.display.last_iteration:
                self.display.show(number, float(entry["lambda"]), float(entry["phi"]), tau)
        self.display.finish()


def _check_readable(path: str) -> None:
    try:
        Path(path).open("rb").close()
    except OSError as exc:
        raise CliError(f"cannot read {path}: {os_reason(exc)}", EXIT_INPUT) from exc


def _remote(
    ns: argparse.Namespace, params: Mapping[str, Any], out_fmt: str | None, progress: JobProgress
) -> tuple[bytes, Mapping[str, Any]]:
    """Smooth on the service; the result file and the report."""
    from geosmooth_client import Client

    with Client(ns.server, api_key=ns.api_key or None) as client:
        result = client.smooth(ns.input, params, weld=ns.weld, progress=progress)
        return result.download(out_fmt), result.report


def _exit_for(exc: Exception, server: str) -> CliError | None:
    """The client library's errors as exit statuses (the library itself knows none)."""
    import geosmooth_client as gc

    if isinstance(exc, gc.ConnectionFailed):
        return CliError(str(exc), EXIT_UNREACHABLE)
    if isinstance(exc, gc.JobFailed):  # --strict on the server: the same status as smooth's
        return CliError(str(exc), EXIT_SHAPE if exc.code == "shape-lost" else EXIT_JOB_FAILED)
    if isinstance(exc, gc.JobCancelled):
        return CliError(str(exc), EXIT_CANCELLED)
    if isinstance(exc, gc.ApiError):
        code = EXIT_SERVER if exc.status >= 500 else EXIT_REJECTED
        verb = "failed" if exc.status >= 500 else "rejected the request"
        return CliError(f"the server {server} {verb}: {exc.message}", code)
    if isinstance(exc, OSError):
        return CliError(f"cannot read {exc.filename or 'the input'}: {os_reason(exc)}", EXIT_INPUT)
    return None


def run(ns: argparse.Namespace, err: TextIO) -> int:
    """Run ``geosmooth submit``; returns the exit status (errors are raised)."""
    from geosmooth_client import JobInterrupted

    started = time.perf_counter()
    params = params_from_args(ns)
    out_fmt = output_format(ns.output, ns.format)
    check_writable(ns.output, "output")
    if ns.report:
        check_writable(ns.report, "report")
    _check_readable(ns.input)

    display = ProgressDisplay(err, enabled=not ns.quiet)
    progress = JobProgress(display)
    try:
        given = params.model_dump(mode="json", exclude_unset=True)
        data, report = _remote(ns, given, out_fmt, progress)
    except JobInterrupted as exc:
        display.finish()
        err.write(f"geosmooth: {exc.message}\n")
        return EXIT_INTERRUPTED
    except Exception as exc:
        display.finish()
        mapped = _exit_for(exc, ns.server)
        if mapped is None:
            raise
        raise mapped from exc
    progress.catch_up(report)
    write_output(ns.output, data, "output")
    if ns.report:
        write_json_report(ns.report, report)
    show_summary(display, report, ns, params, started, wall_label="upload, queue, smooth, download")
    return EXIT_OK
