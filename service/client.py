"""HTTP client of the geosmooth service: ``geosmooth submit``.

:func:`submit` uploads a file as a job, shows the job's progress on stderr, downloads the result
and the report, and returns an exit status. Every failure is one line on stderr.
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Mapping
from pathlib import Path
from typing import IO, Any

import httpx

from service.core.params import SmoothingParams

__all__ = [
    "CLIENT_EXIT_CODES",
    "EXIT_CANCELLED",
    "EXIT_JOB_FAILED",
    "EXIT_REJECTED",
    "EXIT_UNREACHABLE",
    "submit",
]

from service.exit_codes import (
    EXIT_CANCELLED,
    EXIT_INPUT,
    EXIT_INTERRUPTED,
    EXIT_JOB_FAILED,
    EXIT_OK,
    EXIT_OUTPUT,
    EXIT_REJECTED,
    EXIT_SERVER,
    EXIT_UNREACHABLE,
)
from service.exit_codes import SUBMIT_EXIT_CODES as CLIENT_EXIT_CODES

_RECONNECT_SECONDS = 30.0  # keep polling through a server restart this long


class _Fail(Exception):
    def __init__(self, message: str, code: int) -> None:
        super().__init__(message)
        self.message = message
        self.code = code


def _say(err: IO[str], text: str) -> None:
    err.write(text + "\n")
    err.flush()


def _problem_line(response: httpx.Response) -> str:
    """``title: detail (field)`` from a problem+json answer, else the status line."""
    try:
        body = response.json()
    except ValueError:
        body = None
    if isinstance(body, Mapping) and ("title" in body or "detail" in body):
        text = str(body.get("title") or response.reason_phrase)
        if body.get("detail"):
            text += f": {body['detail']}"
        if body.get("field") and str(body["field"]) not in text:
            text += f" (field {body['field']})"
        return " ".join(text.split())
    return f"HTTP {response.status_code} {response.reason_phrase}"


def _params_json(params: SmoothingParams | Mapping[str, Any]) -> str:
    if isinstance(params, SmoothingParams):
        return params.model_dump_json(exclude_defaults=True)
    return json.dumps(dict(params))


def _output_format(output: str, fmt: str | None) -> str | None:
    if fmt:
        return fmt
    if output == "-":
        return None
    from service.io import UnsupportedFormat, detect_format

    try:
        return detect_format(output)
    except UnsupportedFormat:
        return None


def _request(client: httpx.Client, method: str, url: str, **kwargs: Any) -> httpx.Response:
    try:
        return client.request(method, url, **kwargs)
    except httpx.TransportError as exc:
        raise _Fail(
            f"cannot reach {client.base_url}: {exc or type(exc).__name__}", EXIT_UNREACHABLE
        ) from exc


def _check(response: httpx.Response, what: str) -> httpx.Response:
    if response.is_success:
        return response
    line = _problem_line(response)
    if 400 <= response.status_code < 500:
        raise _Fail(f"{what} rejected: {line}", EXIT_REJECTED)
    raise _Fail(f"{what}: server error: {line}", EXIT_SERVER)


def _progress_line(job: Mapping[str, Any]) -> str | None:
    progress = job.get("progress") or None
    if not progress or progress.get("lambda") is None:  # stages before the first lambda
        return None
    text = f"geosmooth: iteration {progress.get('iteration', '?'):>2}"
    for key, label in (("lambda", "lambda"), ("phi", "phi"), ("tau", "tau")):
        if progress.get(key) is not None:
            text += f"  {label}={float(progress[key]):.4e}"
    if progress.get("relative_error") is not None:
        text += f"  rel.error={float(progress['relative_error']):.2e}"
    return text


def _poll(
    client: httpx.Client, status_url: str, poll_interval: float, err: IO[str], quiet: bool
) -> dict[str, Any]:
    """Poll the job until it finishes; tolerates a server restart for a while."""
    last_line: str | None = None
    last_status: str | None = None
    down_since: float | None = None
    while True:
        try:
            response = client.get(status_url)
        except httpx.TransportError as exc:
            now = time.monotonic()
            down_since = down_since or now
            if now - down_since > _RECONNECT_SECONDS:
                raise _Fail(
                    f"lost the server {client.base_url} for {_RECONNECT_SECONDS:.0f} s: {exc}",
                    EXIT_UNREACHABLE,
                ) from exc
            time.sleep(min(1.0, max(poll_interval, 0.1)))
            continue
        down_since = None
        job = _check(response, "status request").json()
        status = job.get("status")
        if not quiet:
            if status != last_status and status in ("queued", "running"):
                _say(err, f"geosmooth: job {job.get('id')} {status}")
            line = _progress_line(job) if status == "running" else None
            if line and line != last_line:
                _say(err, line)
                last_line = line
        last_status = status
        if status in ("succeeded", "failed", "cancelled"):
            return job
        time.sleep(poll_interval)


def _write(target: str, data: bytes, what: str) -> None:
    try:
        if target == "-":
            sys.stdout.buffer.write(data)
            sys.stdout.buffer.flush()
        else:
            Path(target).write_bytes(data)
    except OSError as exc:
        raise _Fail(f"cannot write {what} {target}: {exc.strerror or exc}", EXIT_OUTPUT) from exc


def _finish(
    client: httpx.Client,
    job: dict[str, Any],
    output: str,
    report: str | None,
    fmt: str | None,
) -> dict[str, Any]:
    links = job.get("links") or {}
    result_url = links.get("result") or f"/v1/jobs/{job['id']}/result"
    query = {"format": fmt} if fmt else None
    result = _check(_request(client, "GET", result_url, params=query), "result download")
    _write(output, result.content, "output")
    report_data = job.get("report")
    if report_data is None:
        report_url = links.get("report") or f"/v1/jobs/{job['id']}/report"
        report_data = _check(_request(client, "GET", report_url), "report download").json()
    if report:
        _write(report, (json.dumps(report_data, indent=2) + "\n").encode(), "report")
    return report_data


def _summary(
    report: Mapping[str, Any], source: str, target: str, seconds: float, tolerance: Any
) -> str:
    try:
        from service.cli_progress import format_summary

        tol = float(tolerance) if isinstance(tolerance, int | float) else None
        text = format_summary(
            report, source=source, target=target, wall_seconds=seconds, tolerance=tol
        )
        return text.replace("(read, smooth, write)", "(upload, queue, smooth, download)")
    except (ImportError, KeyError, TypeError, ValueError):
        return (
            f"geosmooth: {source} -> {target}: lambda={report.get('lambda')}"
            f" phi={report.get('phi')} in {seconds:.2f} s"
        )


def submit(
    input_path: str | Path,
    server: str,
    params: SmoothingParams | Mapping[str, Any],
    output: str,
    report: str | None = None,
    fmt: str | None = None,
    quiet: bool = False,
    poll_interval: float = 0.5,
    *,
    stderr: IO[str] | None = None,
    timeout: float = 60.0,
    weld: bool = False,
) -> int:
    """Smooth ``input_path`` on a geosmooth server and save the result.

    Parameters
    ----------
    input_path : str or Path
        PLY, OBJ, XYZ or JSON file (the server tells the format from the file name).
    server : str
        Base URL, e.g. ``http://127.0.0.1:8000``.
    params : SmoothingParams or mapping
        Smoothing parameters (validated again by the server).
    output : str
        Where to write the smoothed geometry (``-``: stdout).
    report : str, optional
        Where to write the job's report (JSON).
    fmt : str, optional
        Output format; default: from the output file name, else the input's format.
    quiet : bool
        Print nothing but errors.
    poll_interval : float
        Seconds between status requests.
    stderr : text stream, optional
        Where progress and errors go (default ``sys.stderr``).
    timeout : float
        Seconds to wait for one HTTP exchange (upload included).
    weld : bool
        Ask the server to weld exactly coincident vertices (the output keeps the input's).

    Returns
    -------
    int
        0 on success; 7 server unreachable, 8 input or parameters rejected (4xx), 9 job
        failed, 10 job cancelled, 3 local input unreadable, 6 output not writable, 1 unexpected
        server answer, 130 interrupted (the job is cancelled on the server).
    """
    err = stderr or sys.stderr
    started = time.monotonic()
    job_id: str | None = None
    client = httpx.Client(base_url=server.rstrip("/"), timeout=timeout)
    try:
        path = Path(input_path)
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise _Fail(f"cannot read {input_path}: {exc.strerror or exc}", EXIT_INPUT) from exc
        files = {"file": (path.name, data, "application/octet-stream")}
        form = {"params": _params_json(params)}
        if weld:
            form["weld"] = "true"
        answer = _check(_request(client, "POST", "/v1/jobs", files=files, data=form), "upload")
        job = answer.json()
        job_id = job["id"]
        status_url = (job.get("links") or {}).get("status") or f"/v1/jobs/{job_id}"
        job = _poll(client, status_url, poll_interval, err, quiet)
        status = job.get("status")
        if status == "failed":
            problem = job.get("error") or {}
            text = (
                " ".join(str(problem.get(k)) for k in ("title", "detail") if problem.get(k))
                or "no details"
            )
            raise _Fail(f"job {job_id} failed: {text}", EXIT_JOB_FAILED)
        if status == "cancelled":
            raise _Fail(f"job {job_id} was cancelled", EXIT_CANCELLED)
        report_data = _finish(client, job, output, report, _output_format(output, fmt))
        if not quiet:
            seconds = time.monotonic() - started
            tolerance = (
                params.tolerance
                if isinstance(params, SmoothingParams)
                else params.get("tolerance", 1e-3)
            )
            _say(err, _summary(report_data, str(input_path), output, seconds, tolerance))
        return EXIT_OK
    except _Fail as exc:
        _say(err, f"geosmooth: error: {' '.join(exc.message.split())}")
        return exc.code
    except KeyboardInterrupt:
        if job_id is not None:
            try:
                client.delete(f"/v1/jobs/{job_id}", timeout=5.0)
                _say(err, f"geosmooth: interrupted; job {job_id} cancelled")
            except httpx.HTTPError:
                _say(err, f"geosmooth: interrupted; job {job_id} may still run on the server")
        return EXIT_INTERRUPTED
    finally:
        client.close()
