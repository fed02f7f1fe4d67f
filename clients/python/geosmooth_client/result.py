"""The outcome of :meth:`~geosmooth_client.Client.smooth`: the job, its report, its geometry.

:class:`Result` (sync) and :class:`AsyncResult` (async) fetch the result lazily: ``download``
returns the file in any format the service writes, ``save`` writes it, ``geometry`` gives the
JSON format's object and ``arrays`` the points, faces, edges and polylines (numpy arrays when
numpy is installed, nested lists otherwise).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from geosmooth_client.models import Job, Report

__all__ = ["Arrays", "AsyncResult", "Result", "arrays_from_geometry", "format_for_path"]


@dataclass(frozen=True)
class Arrays:
    """A geometry as arrays (0-based indices, the input's vertex count and order).

    Attributes
    ----------
    points : ndarray (n, s) or list
        Smoothed points.
    faces, edges : ndarray (k, 3) / (k, 2), list, or None
        Triangles and edges that belong to no polyline.
    polylines : list of dict
        ``{"indices": [...], "closed": bool}`` per polyline.
    """

    points: Any
    faces: Any = None
    edges: Any = None
    polylines: list[dict[str, Any]] = field(default_factory=list)


def arrays_from_geometry(obj: dict[str, Any]) -> Arrays:
    """The JSON format's object as :class:`Arrays` (numpy when importable)."""
    try:
        import numpy as np
    except ImportError:  # numpy is optional: nested lists then
        return Arrays(obj["points"], obj.get("faces"), obj.get("edges"), obj.get("polylines", []))

    def ints(key: str, width: int) -> Any:
        value = obj.get(key)
        return None if value is None else np.asarray(value, dtype=np.int64).reshape(-1, width)

    return Arrays(
        points=np.asarray(obj["points"], dtype=np.float64),
        faces=ints("faces", 3),
        edges=ints("edges", 2),
        polylines=list(obj.get("polylines", [])),
    )


def format_for_path(path: str | os.PathLike[str], fmt: str | None) -> str | None:
    """``fmt``, else the file name's extension (``bunny.obj`` -> ``obj``), else ``None``."""
    if fmt:
        return fmt
    suffix = Path(path).suffix.lower().lstrip(".")
    return suffix or None


class _Fetcher(Protocol):
    """What a :class:`Result` needs of its client (:class:`~geosmooth_client.Client`)."""

    def report(self, job_id: str) -> Report: ...

    def download(self, job_id: str, fmt: str | None = None) -> bytes: ...


class _AsyncFetcher(Protocol):
    """What an :class:`AsyncResult` needs of its client (:class:`~geosmooth_client.AsyncClient`)."""

    async def report(self, job_id: str) -> Report: ...

    async def download(self, job_id: str, fmt: str | None = None) -> bytes: ...


class Result:
    """A succeeded job of a :class:`~geosmooth_client.Client`.

    Attributes
    ----------
    job : Job
        The job as it finished.
    """

    def __init__(self, client: _Fetcher, job: Job) -> None:
        self.job = job
        self._client = client
        self._report = job.report

    @property
    def id(self) -> str:
        return self.job.id

    @property
    def report(self) -> Report:
        """The diagnostics (fetched once if the job did not carry them)."""
        if self._report is None:
            self._report = self._client.report(self.job.id)
        return self._report

    def download(self, fmt: str | None = None) -> bytes:
        """The smoothed geometry as a file in ``fmt`` (default: the input's format)."""
        return self._client.download(self.job.id, fmt)

    def save(self, path: str | os.PathLike[str], fmt: str | None = None) -> Path:
        """Write the smoothed geometry; the format defaults to the file name's extension."""
        target = Path(path)
        target.write_bytes(self.download(format_for_path(target, fmt)))
        return target

    def geometry(self) -> dict[str, Any]:
        """The smoothed geometry as the JSON format's object."""
        data: dict[str, Any] = json.loads(self.download("json"))
        return data

    def arrays(self) -> Arrays:
        """The smoothed geometry as arrays."""
        return arrays_from_geometry(self.geometry())

    def __repr__(self) -> str:
        return f"Result(job={self.job.id!r}, status={self.job.status!r})"


class AsyncResult:
    """A succeeded job of an :class:`~geosmooth_client.AsyncClient`.

    The attributes of :class:`Result` (``job``, ``id``, ``report``) as they are, its methods
    (``download``, ``save``, ``geometry``, ``arrays``) awaited.

    ``await client.smooth(...)`` builds it with :meth:`create`, which fetches the report if the
    job did not carry it, so ``result.report.phi`` works as with the sync client.
    """

    def __init__(self, client: _AsyncFetcher, job: Job, report: Report | None = None) -> None:
        self.job = job
        self._client = client
        self._report = report if report is not None else job.report

    @classmethod
    async def create(cls, client: _AsyncFetcher, job: Job) -> AsyncResult:
        """The result of ``job``, with its report (fetched once if the job did not carry it)."""
        report = job.report if job.report is not None else await client.report(job.id)
        return cls(client, job, report)

    @property
    def id(self) -> str:
        return self.job.id

    @property
    def report(self) -> Report:
        """The diagnostics, as :attr:`Result.report` (an attribute, not a coroutine)."""
        if self._report is None:
            raise RuntimeError(
                "this AsyncResult has no report: build it with 'await AsyncResult.create(...)'"
                " (AsyncClient.smooth does)"
            )
        return self._report

    async def download(self, fmt: str | None = None) -> bytes:
        return await self._client.download(self.job.id, fmt)

    async def save(self, path: str | os.PathLike[str], fmt: str | None = None) -> Path:
        target = Path(path)
        target.write_bytes(await self.download(format_for_path(target, fmt)))
        return target

    async def geometry(self) -> dict[str, Any]:
        data: dict[str, Any] = json.loads(await self.download("json"))
        return data

    async def arrays(self) -> Arrays:
        return arrays_from_geometry(await self.geometry())

    def __repr__(self) -> str:
        return f"AsyncResult(job={self.job.id!r}, status={self.job.status!r})"
