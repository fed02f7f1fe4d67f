"""The asyncio client: :class:`AsyncClient`, the methods of :class:`Client` as coroutines.

Requests, retries and job watching are the shared code of :mod:`geosmooth_client._protocol`;
this module only awaits them. Cancelling the task that runs :meth:`AsyncClient.smooth` (as
``asyncio.run`` does on Ctrl-C) cancels the job on the service before the cancellation
propagates; cancelling an upload before its end leaves no job at all.
"""

from __future__ import annotations

import asyncio
import itertools
from collections.abc import AsyncIterator, Awaitable, Callable
from typing import Any

import httpx

from geosmooth_client._protocol import (
    JOBS,
    USER_AGENT,
    ProgressCallback,
    RetryPolicy,
    Upload,
    Watch,
    check,
    job_path,
    params_dict,
    transport_error,
)
from geosmooth_client.errors import ConnectionFailed, NotFound
from geosmooth_client.models import Job, JobList, Report
from geosmooth_client.result import AsyncResult
from geosmooth_client.sse import SSEDecoder

__all__ = ["AsyncClient"]

_EVENTS_READ_TIMEOUT = 45.0


class AsyncClient:
    """A connection to one geosmooth service, for asyncio code.

    The parameters are those of :class:`Client` (``transport``: an
    :class:`httpx.AsyncBaseTransport`).
    """

    def __init__(
        self,
        url: str,
        api_key: str | None = None,
        *,
        timeout: float = 60.0,
        retry: RetryPolicy | None = None,
        reconnect_seconds: float = 30.0,
        cancel_grace: float = 30.0,
        transport: httpx.AsyncBaseTransport | None = None,
    ) -> None:
        headers = {"User-Agent": USER_AGENT}
        if api_key:
            headers["Authorization"] = f"Bearer {api_key}"
        self.url = url.rstrip("/")
        self.retry = retry or RetryPolicy()
        self.reconnect_seconds = reconnect_seconds
        self.cancel_grace = cancel_grace
        self._events: bool | None = None
        self._http = httpx.AsyncClient(
            base_url=self.url, headers=headers, timeout=timeout, transport=transport
        )

    async def __aenter__(self) -> AsyncClient:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.aclose()

    async def aclose(self) -> None:
        """Close the connections."""
        await self._http.aclose()

    async def _send(self, method: str, path: str, **kwargs: Any) -> httpx.Response:
        return await self._retrying(lambda: self._http.request(method, path, **kwargs))

    async def _retrying(self, send: Callable[[], Awaitable[httpx.Response]]) -> httpx.Response:
        for attempt in itertools.count():
            try:
                response = await send()
            except httpx.TransportError as exc:
                wait = self.retry.delay(attempt, None)
                if wait is None:
                    raise transport_error(self.url, exc) from exc
            else:
                wait = self.retry.delay(attempt, response)
                if wait is None:
                    return check(response)
            await asyncio.sleep(wait)
        raise AssertionError("unreachable")  # pragma: no cover

    # ------------------------------------------------------------------ endpoints

    async def submit(
        self,
        source: Any,
        params: Any = None,
        *,
        fmt: str | None = None,
        filename: str | None = None,
        weld: bool = False,
        webhook_url: str | None = None,
        idempotency_key: str | None = None,
        **param_values: Any,
    ) -> Job:
        """See :meth:`Client.submit`."""
        upload = Upload.build(
            source,
            params_dict(params, param_values),
            fmt=fmt,
            filename=filename,
            weld=weld,
            webhook_url=webhook_url,
            idempotency_key=idempotency_key,
        )
        return Job.from_dict((await self._retrying(lambda: self._post_upload(upload))).json())

    async def _post_upload(self, upload: Upload) -> httpx.Response:
        body, kwargs = upload.request()
        task = asyncio.ensure_future(self._http.post(JOBS, **kwargs))
        try:
            return await asyncio.shield(task)
        except asyncio.CancelledError:
            if not body.stop():  # stopped before the end of the body: no job can exist
                task.cancel()
                raise
            await self._cancel_after_upload(task)
            raise
        finally:
            if task.done():
                body.close()

    async def _cancel_after_upload(self, task: asyncio.Future[httpx.Response]) -> None:
        """The whole file went out: wait for the job id, then cancel that job."""
        try:
            response = await asyncio.wait_for(task, self.cancel_grace)
        except (TimeoutError, httpx.HTTPError):
            return
        if response.is_success:
            await self._cancel_quietly(str(response.json()["id"]))

    async def get(self, job_id: str) -> Job:
        """See :meth:`Client.get`."""
        return Job.from_dict((await self._send("GET", job_path(job_id))).json())

    async def list(
        self, *, status: str | None = None, offset: int = 0, limit: int = 50
    ) -> JobList:
        """See :meth:`Client.list`."""
        query: dict[str, Any] = {"offset": offset, "limit": limit}
        if status:
            query["status"] = status
        return JobList.from_dict((await self._send("GET", JOBS, params=query)).json())

    async def iter_jobs(
        self, *, status: str | None = None, page_size: int = 100
    ) -> AsyncIterator[Job]:
        """Every job, page after page."""
        offset = 0
        while True:
            page = await self.list(status=status, offset=offset, limit=page_size)
            for job in page.items:
                yield job
            offset += len(page.items)
            if not page.items or page.links.next is None:
                return

    async def report(self, job_id: str) -> Report:
        """See :meth:`Client.report`."""
        return Report((await self._send("GET", job_path(job_id, "/report"))).json())

    async def download(self, job_id: str, fmt: str | None = None) -> bytes:
        """See :meth:`Client.download`."""
        query = {"format": fmt} if fmt else None
        return (await self._send("GET", job_path(job_id, "/result"), params=query)).content

    async def cancel(self, job_id: str) -> Job:
        """See :meth:`Client.cancel`."""
        job = await self.get(job_id)
        if job.finished:
            return job
        response = await self._send("DELETE", job_path(job_id))
        return job if response.status_code == 204 else Job.from_dict(response.json())

    async def delete(self, job_id: str) -> None:
        """See :meth:`Client.delete`."""
        if (await self._send("DELETE", job_path(job_id))).status_code == 200:
            await self._send("DELETE", job_path(job_id))

    async def _cancel_quietly(self, job_id: str) -> str:
        try:
            return (await self.cancel(job_id)).status
        except Exception:
            return "unknown"

    # ------------------------------------------------------------------ waiting

    @property
    def uses_events(self) -> bool | None:
        """Whether the service streams job events (``None`` until a wait found out)."""
        return self._events

    def _has_events(self) -> bool:
        """Whether the service has (or may have) the events stream."""
        return self._events is not False

    async def wait(
        self,
        job_id: str,
        *,
        progress: ProgressCallback | None = None,
        timeout: float | None = None,
        poll_interval: float = 0.5,
        job: Job | None = None,
    ) -> Job:
        """See :meth:`Client.wait`."""
        watch = Watch(job_id, progress, timeout, self.reconnect_seconds, job)
        while True:
            watch.remaining()
            try:
                final = await self._follow(watch, poll_interval)
            except ConnectionFailed as exc:
                await asyncio.sleep(watch.lost(exc))
                continue
            if final is not None:
                return final

    async def _follow(self, watch: Watch, poll_interval: float) -> Job | None:
        if self._events is not False:
            final = await self._read_events(watch)
            if final is not None or self._has_events():
                return final
        final = watch.on_job(await self._get_once(watch.job_id))
        if final is None:
            await asyncio.sleep(watch.sleep_time(poll_interval))
        return final

    async def _get_once(self, job_id: str) -> Job:
        try:
            response = await self._http.get(job_path(job_id))
        except httpx.TransportError as exc:
            raise transport_error(self.url, exc) from exc
        return Job.from_dict(check(response).json())

    async def _read_events(self, watch: Watch) -> Job | None:
        headers = {"Accept": "text/event-stream"}
        if watch.last_event_id is not None:
            headers["Last-Event-ID"] = watch.last_event_id
        left = watch.remaining()
        read = _EVENTS_READ_TIMEOUT if left is None else min(_EVENTS_READ_TIMEOUT, left + 0.1)
        timeout = httpx.Timeout(self._http.timeout.connect, read=read)
        decoder = SSEDecoder()
        url = job_path(watch.job_id, "/events")
        try:
            async with self._http.stream("GET", url, headers=headers, timeout=timeout) as response:
                if response.status_code == 404:
                    await response.aread()
                    job = await self._get_once(watch.job_id)  # NotFound for an unknown job
                    self._events = False
                    return watch.on_job(job)
                if not response.is_success:
                    await response.aread()
                    check(response)
                self._events = True
                async for line in response.aiter_lines():
                    event = decoder.feed(line)
                    watch.last_event_id = decoder.last_event_id
                    final = watch.on_event(event) if event is not None else None
                    if final is not None:
                        return final
        except httpx.TransportError as exc:
            raise transport_error(self.url, exc) from exc
        return None

    # ------------------------------------------------------------------ all in one

    async def smooth(
        self,
        source: Any,
        params: Any = None,
        *,
        fmt: str | None = None,
        filename: str | None = None,
        weld: bool = False,
        progress: ProgressCallback | None = None,
        timeout: float | None = None,
        **param_values: Any,
    ) -> AsyncResult:
        """See :meth:`Client.smooth`; cancelling the task cancels the job."""
        job = await self.submit(
            source, params, fmt=fmt, filename=filename, weld=weld, **param_values
        )
        try:
            if progress is not None:
                progress(job)
            job = await self.wait(job.id, progress=progress, timeout=timeout, job=job)
        except NotFound:
            raise
        except BaseException:  # cancelled, timed out, unreachable: leave no job running
            await asyncio.shield(self._cancel_quietly(job.id))
            raise
        return AsyncResult(self, job.raise_for_status())
