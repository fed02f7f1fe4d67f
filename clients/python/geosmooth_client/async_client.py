"""The asyncio client: :class:`AsyncClient`, the methods of the sync client as coroutines.

The sync client is :class:`~geosmooth_client.Client`. Requests, retries and job watching are the
shared code of :mod:`geosmooth_client._protocol`; this module only awaits them. Cancelling the
task that runs :meth:`AsyncClient.smooth` (as ``asyncio.run`` does on Ctrl-C) cancels the job on
the service before the cancellation propagates; cancelling an upload before its end leaves no
job at all.
"""

from __future__ import annotations

import asyncio
import itertools
from collections.abc import AsyncIterator, Awaitable, Callable
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
from geosmooth_client.errors import ConnectionFailed, NotFound, raise_for_status
from geosmooth_client.models import Job, JobList, Report
from geosmooth_client.result import AsyncResult

__all__ = ["AsyncClient"]



class AsyncClient(ClientBase[httpx.AsyncClient]):
    """A connection to one geosmooth service, for asyncio code.

    The parameters are those of :class:`~geosmooth_client.Client` (``transport``: an
    :class:`httpx.AsyncBaseTransport`).
    """

    def _connect(
        self, timeout: float, transport: httpx.AsyncBaseTransport | None
    ) -> httpx.AsyncClient:
        return httpx.AsyncClient(
            base_url=self.url, headers=self.headers, timeout=timeout, transport=transport
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
        weld: bool | None = None,
        webhook_url: str | None = None,
        idempotency_key: str | None = None,
        **param_values: Any,
    ) -> Job:
        """See :meth:`~geosmooth_client.Client.submit`."""
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
        """See :meth:`~geosmooth_client.Client.get`."""
        return Job.from_dict((await self._send("GET", job_path(job_id))).json())

    async def list(
        self, *, status: str | None = None, offset: int = 0, limit: int = 50
    ) -> JobList:
        """See :meth:`~geosmooth_client.Client.list`."""
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
        """See :meth:`~geosmooth_client.Client.report`."""
        return Report((await self._send("GET", job_path(job_id, "/report"))).json())

    async def download(self, job_id: str, fmt: str | None = None) -> bytes:
        """See :meth:`~geosmooth_client.Client.download`."""
        query = {"output_format": fmt} if fmt else None
        return (await self._send("GET", job_path(job_id, "/result"), params=query)).content

    async def cancel(self, job_id: str) -> Job:
        """See :meth:`~geosmooth_client.Client.cancel`."""
        return Job.from_dict((await self._send("POST", job_path(job_id, "/cancel"))).json())

    async def delete(self, job_id: str) -> None:
        """See :meth:`~geosmooth_client.Client.delete`."""
        await self._send("DELETE", job_path(job_id))

    async def _cancel_quietly(self, job_id: str) -> str:
        try:
            return (await self.cancel(job_id)).status
        except Exception:
            return "unknown"

    # ------------------------------------------------------------------ waiting

    async def wait(
        self,
        job_id: str,
        *,
        progress: ProgressCallback | None = None,
        timeout: float | None = None,
        poll_interval: float = 0.5,
        job: Job | None = None,
    ) -> Job:
        """See :meth:`~geosmooth_client.Client.wait`."""
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
        """One look at the job: its events stream until it ends, or one poll."""
        if self._has_events():
            final = await self._read_events(watch)
        else:
            final = watch.on_job(await self._get_once(watch.job_id))
        if final is None:  # a poll, or a stream that ended early: pause before the next look
            await asyncio.sleep(watch.sleep_time(poll_interval))
        return final

    async def _get_once(self, job_id: str) -> Job:
        try:
            response = await self._http.get(job_path(job_id))
        except httpx.TransportError as exc:
            raise transport_error(self.url, exc) from exc
        return Job.from_dict(check(response).json())

    async def _read_events(self, watch: Watch) -> Job | None:
        request = self._events_request(watch, self._http.timeout.connect)
        try:
            async with self._http.stream(**request) as response:
                if response.status_code == 404:
                    await response.aread()
                    job = await self._get_once(watch.job_id)
                    self._events = False
                    return watch.on_job(job)
                if not response.is_success:
                    await response.aread()
                    check(response)
                self._events = True
                watch.new_stream()
                async for line in response.aiter_lines():
                    final = watch.on_line(line)
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
        progress: ProgressCallback | None = None,
        timeout: float | None = None,
        **submit_options: Any,
    ) -> AsyncResult:
        """See :meth:`~geosmooth_client.Client.smooth`; cancelling the task cancels the job."""
        job = await self.submit(source, params, **submit_options)
        try:
            if progress is not None:
                progress(job)
            job = await self.wait(job.id, progress=progress, timeout=timeout, job=job)
        except NotFound:
            raise
        except BaseException:  # cancelled, timed out, unreachable: leave no job running
            await asyncio.shield(self._cancel_quietly(job.id))
            raise
        return await AsyncResult.create(self, raise_for_status(job))
