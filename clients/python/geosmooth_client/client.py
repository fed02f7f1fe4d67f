"""The synchronous client: :class:`Client`.

Every method maps to one endpoint of the service (``submit`` → ``POST /v1/jobs``, ``get`` →
``GET /v1/jobs/{id}``, ...) and :meth:`Client.smooth` chains them: upload, follow the job (its
events stream, or polling on services without one), return a :class:`Result`. Nothing here
prints; failures are the typed errors of :mod:`geosmooth_client.errors`.

Ctrl-C is safe: during the upload it stops the request before the service can create a job, or
(when the whole file already went out) waits briefly for the job id and cancels that job;
during :meth:`Client.smooth`'s wait it cancels the job. Either way :class:`JobInterrupted`
(a ``KeyboardInterrupt``) says what happened to the job.
"""

from __future__ import annotations

import contextlib
import itertools
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import httpx

from geosmooth_client._protocol import (
    JOBS,
    ClientBase,
    ProgressCallback,
    Watch,
    check,
    job_path,
    transport_error,
)
from geosmooth_client._upload import Upload, params_dict
from geosmooth_client.errors import ConnectionFailed, JobInterrupted, NotFound, raise_for_status
from geosmooth_client.models import Job, JobList, Report
from geosmooth_client.result import Result

__all__ = ["Client"]



class Client(ClientBase[httpx.Client]):
    """A connection to one geosmooth service.

    Parameters
    ----------
    url : str
        Base URL, e.g. ``http://127.0.0.1:8000``.
    api_key : str, optional
        Sent as ``Authorization: Bearer <key>``.
    timeout : float
        Seconds for one HTTP exchange (connect, and each read or write).
    retry : RetryPolicy, optional
        When to send a request again (connection failures, 429/502/503/504).
    reconnect_seconds : float
        How long :meth:`wait` keeps trying while the service is unreachable (a restart).
    cancel_grace : float
        After Ctrl-C once the whole file was uploaded: seconds to wait for the job id so that
        the job can be cancelled (a second Ctrl-C stops waiting).
    transport : httpx.BaseTransport, optional
        Passed to :class:`httpx.Client` (e.g. a Unix socket transport).
    """

    def _connect(self, timeout: float, transport: httpx.BaseTransport | None) -> httpx.Client:
        return httpx.Client(
            base_url=self.url, headers=self.headers, timeout=timeout, transport=transport
        )

    # ------------------------------------------------------------------ plumbing

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Close the connections."""
        self._http.close()

    def _send(self, method: str, path: str, **kwargs: Any) -> httpx.Response:
        """One request with retries; a typed error unless it succeeded."""
        return self._retrying(lambda: self._http.request(method, path, **kwargs))

    def _retrying(self, send: Callable[[], httpx.Response]) -> httpx.Response:
        for attempt in itertools.count():
            try:
                response = send()
            except httpx.TransportError as exc:
                wait = self.retry.delay(attempt, None)
                if wait is None:
                    raise transport_error(self.url, exc) from exc
            else:
                wait = self.retry.delay(attempt, response)
                if wait is None:
                    return check(response)
            time.sleep(wait)
        raise AssertionError("unreachable")  # pragma: no cover

    # ------------------------------------------------------------------ endpoints

    def submit(
        self,
        source: Any,
        params: Any = None,
        *,
        fmt: str | None = None,
        filename: str | None = None,
        weld: bool | None = None,
        webhook_url: str | None = None,
        idempotency_key: str | None = None,
        **param_values: Any,
    ) -> Job:
        """Upload an input as a job (``POST /v1/jobs``); returns the queued job.

        Parameters
        ----------
        source : path, bytes, mapping or array_like
            A file, its bytes, a geometry mapping (``{"points", "faces", ...}``) or points.
        params : mapping or pydantic model, optional
            Smoothing parameters; ``**param_values`` (``tau=0.5``) are added to them.
        fmt : str, optional
            Input format, when neither the file name nor the content tells it.
        filename : str, optional
            Name sent with the file (default: the path's name).
        weld : bool, optional
            Have the service weld exactly coincident vertices (default: the format's default,
            yes for STL and GLB).
        webhook_url : str, optional
            URL the service POSTs the finished job to.
        idempotency_key : str, optional
            Sent as ``Idempotency-Key`` (default: a new random key, reused by the retries of
            this call, so a retried upload never makes two jobs).

        Raises
        ------
        ApiError
            The service refused the input (400, 413, 415, 422 ...).
        ConnectionFailed
            The service cannot be reached (after the retries).
        JobInterrupted
            Ctrl-C during the upload (see the class).
        """
        upload = Upload.build(
            source,
            params_dict(params, param_values),
            fmt=fmt,
            filename=filename,
            weld=weld,
            webhook_url=webhook_url,
            idempotency_key=idempotency_key,
        )
        return Job.from_dict(self._retrying(lambda: self._post_upload(upload)).json())

    def _post_upload(self, upload: Upload) -> httpx.Response:
        """Send one attempt from a helper thread, so that Ctrl-C can be handled cleanly."""
        body, kwargs = upload.request()
        box: dict[str, Any] = {}
        done = threading.Event()

        def post() -> None:
            try:
                box["response"] = self._http.post(JOBS, **kwargs)
            except BaseException as exc:  # handed to the calling thread
                box["error"] = exc
            finally:
                body.close()
                done.set()

        threading.Thread(target=post, name="geosmooth-upload", daemon=True).start()
        try:
            while not done.wait(0.2):
                pass
        except KeyboardInterrupt as exc:
            raise self._interrupted_upload(body.stop(), done, box) from exc
        if "error" in box:
            raise box["error"]
        response: httpx.Response = box["response"]
        return response

    def _interrupted_upload(
        self, sent: bool, done: threading.Event, box: dict[str, Any]
    ) -> JobInterrupted:
        """Ctrl-C during an upload: make sure no job is left running, say what happened."""
        if not sent:  # the body stops before its end: the service cannot make a job of it
            return JobInterrupted(None, "not-created")
        with contextlib.suppress(KeyboardInterrupt):  # a second Ctrl-C stops the wait
            done.wait(self.cancel_grace)
        response = box.get("response")
        if response is None:
            return JobInterrupted(None, "unknown")
        if not response.is_success:
            return JobInterrupted(None, "not-created")
        job_id = str(response.json()["id"])
        return JobInterrupted(job_id, self._cancel_quietly(job_id))

    def get(self, job_id: str) -> Job:
        """The job's current state (``GET /v1/jobs/{id}``)."""
        return Job.from_dict(self._send("GET", job_path(job_id)).json())

    def list(self, *, status: str | None = None, offset: int = 0, limit: int = 50) -> JobList:
        """A page of jobs, newest first (``GET /v1/jobs``)."""
        query: dict[str, Any] = {"offset": offset, "limit": limit}
        if status:
            query["status"] = status
        return JobList.from_dict(self._send("GET", JOBS, params=query).json())

    def iter_jobs(self, *, status: str | None = None, page_size: int = 100) -> Iterator[Job]:
        """Every job, page after page."""
        offset = 0
        while True:
            page = self.list(status=status, offset=offset, limit=page_size)
            yield from page.items
            offset += len(page.items)
            if not page.items or page.links.next is None:
                return

    def report(self, job_id: str) -> Report:
        """Diagnostics of a succeeded job (``GET /v1/jobs/{id}/report``)."""
        return Report(self._send("GET", job_path(job_id, "/report")).json())

    def download(self, job_id: str, fmt: str | None = None) -> bytes:
        """The smoothed geometry, in ``fmt`` (default: the input's format)."""
        query = {"output_format": fmt} if fmt else None
        return self._send("GET", job_path(job_id, "/result"), params=query).content

    def cancel(self, job_id: str) -> Job:
        """Cancel a queued or running job (``POST /v1/jobs/{id}/cancel``); the job stays readable.

        A finished job is returned unchanged (not deleted).
        """
        return Job.from_dict(self._send("POST", job_path(job_id, "/cancel")).json())

    def delete(self, job_id: str) -> None:
        """Delete a job and its files (a queued or running job is cancelled first); then 404."""
        self._send("DELETE", job_path(job_id))

    def _cancel_quietly(self, job_id: str) -> str:
        """Best effort (Ctrl-C, timeout): the job's status afterwards, or ``"unknown"``."""
        try:
            return self.cancel(job_id).status
        except Exception:
            return "unknown"

    # ------------------------------------------------------------------ waiting

    def wait(
        self,
        job_id: str,
        *,
        progress: ProgressCallback | None = None,
        timeout: float | None = None,
        poll_interval: float = 0.5,
        job: Job | None = None,
    ) -> Job:
        """Follow a job until it is finished; returns its final state (any final status).

        Reads the job's events stream (``GET /v1/jobs/{id}/events``) and polls
        ``GET /v1/jobs/{id}`` on services that have none; rides out a restart of the service
        for ``reconnect_seconds``.

        Parameters
        ----------
        progress : callable, optional
            ``progress(job)`` on every change of status or progress.
        timeout : float, optional
            Raise :class:`~geosmooth_client.errors.WaitTimeout` after this many seconds (the job
            keeps running).
        poll_interval : float
            Seconds between polls (services without events).
        job : Job, optional
            The state already known (not reported again).
        """
        watch = Watch(job_id, progress, timeout, self.reconnect_seconds, job)
        while True:
            watch.remaining()
            try:
                final = self._follow(watch, poll_interval)
            except ConnectionFailed as exc:
                time.sleep(watch.lost(exc))
                continue
            if final is not None:
                return final

    def _follow(self, watch: Watch, poll_interval: float) -> Job | None:
        """One look at the job: its events stream until it ends, or one poll."""
        if self._has_events():
            final = self._read_events(watch)
        else:
            final = watch.on_job(self._get_once(watch.job_id))
        if final is None:  # a poll, or a stream that ended early: pause before the next look
            time.sleep(watch.sleep_time(poll_interval))
        return final

    def _get_once(self, job_id: str) -> Job:
        try:
            response = self._http.get(job_path(job_id))
        except httpx.TransportError as exc:
            raise transport_error(self.url, exc) from exc
        return Job.from_dict(check(response).json())

    def _read_events(self, watch: Watch) -> Job | None:
        """Read the events stream until the job is final or the stream ends."""
        request = self._events_request(watch, self._http.timeout.connect)
        try:
            with self._http.stream(**request) as response:
                if response.status_code == 404:  # an unknown job (NotFound), or no events
                    response.read()
                    job = self._get_once(watch.job_id)
                    self._events = False
                    return watch.on_job(job)
                if not response.is_success:
                    response.read()
                    check(response)
                self._events = True
                watch.new_stream()
                for line in response.iter_lines():
                    final = watch.on_line(line)
                    if final is not None:
                        return final
        except httpx.TransportError as exc:
            raise transport_error(self.url, exc) from exc
        return None

    # ------------------------------------------------------------------ all in one

    def smooth(
        self,
        source: Any,
        params: Any = None,
        *,
        progress: ProgressCallback | None = None,
        timeout: float | None = None,
        **submit_options: Any,
    ) -> Result:
        """Submit, wait, and return the :class:`Result` of a succeeded job.

        ``source``, ``params`` and ``**submit_options`` (``fmt``, ``filename``, ``weld``, the
        parameter values such as ``tau=0.5``) are those of :meth:`submit`; ``progress`` and
        ``timeout`` those of :meth:`wait`. If the call ends without a result (Ctrl-C, timeout),
        the job is cancelled on the service.

        Raises
        ------
        JobFailed, JobCancelled
            The job ended failed (``.job.error`` says why) or was cancelled.
        JobInterrupted
            Ctrl-C; the job was cancelled (see its ``status``).
        WaitTimeout, ApiError, ConnectionFailed
            As :meth:`submit` and :meth:`wait`.
        """
        job = self.submit(source, params, **submit_options)
        try:
            if progress is not None:
                progress(job)
            job = self.wait(job.id, progress=progress, timeout=timeout, job=job)
        except KeyboardInterrupt as exc:
            raise JobInterrupted(job.id, self._cancel_quietly(job.id)) from exc
        except NotFound:
            raise
        except BaseException:  # timed out, unreachable: leave no job running
            self._cancel_quietly(job.id)
            raise
        return Result(self, raise_for_status(job))
