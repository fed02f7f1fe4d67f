"""What every backend checks before it accepts a job (the shared half of ``submit``).

* the format name and the parameters;
* idempotency: the fingerprint of a request (:func:`request_hash`) that an ``Idempotency-Key``
  is bound to;
* the resource estimate against the per-job memory limit (:func:`admit_size`);
* free space in the store (:func:`check_space`): a submit that would leave less than
  ``min_free_bytes`` is refused with 507 before anything is written, so running jobs keep room
  for their results and the store for its metadata.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from service.jobs.errors import JobTooLarge, StorageError, StorageFull, storage_error
from service.jobs.limits import check_admission
from service.jobs.queue import JobInput, JobSize

if TYPE_CHECKING:
    from service.core.params import SmoothingParams
    from service.jobs.embedded.store import NewJob

__all__ = [
    "admit_size",
    "check_format",
    "check_space",
    "input_size",
    "new_job",
    "request_hash",
    "storage_errors",
    "validate_params",
]


def check_format(fmt: str) -> str:
    """The normalised format name (``ValueError`` for one geosmooth does not know)."""
    from service.io import FORMATS

    fmt = str(fmt).lower()
    if fmt not in FORMATS:
        raise ValueError(f"unknown format {fmt!r}; expected one of {', '.join(FORMATS)}")
    return fmt


def validate_params(params: SmoothingParams | Mapping[str, Any]) -> SmoothingParams:
    """``params`` as :class:`SmoothingParams` (``pydantic.ValidationError`` if invalid)."""
    from service.core.params import SmoothingParams

    if isinstance(params, SmoothingParams):
        return params
    return SmoothingParams.model_validate(dict(params))


def input_size(data: JobInput) -> int:
    """Bytes of the input."""
    return data.stat().st_size if isinstance(data, Path) else len(data)


def _digest(data: JobInput) -> str:
    h = hashlib.sha256()
    if isinstance(data, Path):
        with open(data, "rb") as fh:
            for block in iter(lambda: fh.read(1024 * 1024), b""):
                h.update(block)
    else:
        h.update(data)
    return h.hexdigest()


def request_hash(data: JobInput, fmt: str, params: dict[str, Any], **fields: Any) -> str:
    """Fingerprint of a submit request: the input's SHA-256 and every other member."""
    meta = json.dumps({"fmt": fmt, "params": params, **fields}, sort_keys=True)
    return hashlib.sha256(f"{_digest(data)}\n{meta}".encode()).hexdigest()


def admit_size(
    data: JobInput,
    fmt: str,
    params: SmoothingParams,
    *,
    weld: bool,
    size: JobSize | None,
    limit: int | None,
) -> SmoothingParams:
    """Refuse the job if its memory estimate is above ``limit`` (reads the input when the
    caller did not give its ``size``). Returns ``params``, with ``tile_points`` set when only a
    tiled run fits (:func:`service.jobs.tiles.auto_tile_points`, issue 23)."""
    if limit is None:
        return params
    if size is None:
        from service.io import read_geometry

        size = JobSize.of(read_geometry(data, fmt, weld=weld).geometry)
    try:
        check_admission(size, params, limit)
    except JobTooLarge:
        from service.jobs.tiles import auto_tile_points, tile_workers

        tile = None if params.tile_points else auto_tile_points(size, params, limit,
                                                                 tile_workers())  # fmt: skip
        if tile is None:
            raise
        return params.model_copy(update={"tile_points": tile})
    return params


def check_space(directory: Path, needed: int, min_free: int) -> None:
    """Refuse (``StorageFull``) when ``needed`` bytes would leave less than ``min_free``."""
    try:
        st = os.statvfs(directory)
    except OSError as exc:
        raise storage_error(exc) from None  # type: ignore[misc]
    if st.f_bavail * st.f_frsize < needed + min_free:
        raise StorageFull("the job store is out of space; try again later")


@contextlib.contextmanager
def storage_errors() -> Iterator[None]:
    """Turn file-system and database failures into :class:`StorageFull` /
    :class:`StorageUnavailable` (no paths or driver text in the message)."""
    try:
        yield
    except StorageError:
        raise
    except Exception as exc:
        typed = storage_error(exc)
        if typed is None:
            raise
        raise typed from exc


def new_job(
    data: JobInput,
    fmt: str,
    params: SmoothingParams | Mapping[str, Any],
    filename: str | None,
    *,
    weld: bool,
    tenant: str | None,
    webhook_url: str | None,
    idempotency_key: str | None,
    size: JobSize | None,
    memory_limit: int | None,
    max_attempts: int,
) -> NewJob:
    """The checked job of a ``submit`` (every backend's first half): format, parameters,
    the request's fingerprint when an ``Idempotency-Key`` is given, the memory estimate.

    Raises
    ------
    ValueError, pydantic.ValidationError, JobTooLarge
        Unknown format, invalid parameters, an estimate above ``memory_limit``.
    """
    import uuid

    from service.jobs.embedded.store import NewJob

    fmt = check_format(fmt)
    smoothing = validate_params(params)
    stored = smoothing.model_dump(mode="json", exclude_none=True)
    digest = None
    if idempotency_key is not None:
        digest = request_hash(data, fmt, stored, filename=filename, weld=weld,
                              webhook_url=webhook_url)  # fmt: skip
    smoothing = admit_size(data, fmt, smoothing, weld=weld, size=size, limit=memory_limit)
    stored = smoothing.model_dump(mode="json", exclude_none=True)
    return NewJob(
        uuid.uuid4().hex, fmt, filename, stored, input_size(data), max_attempts, weld, tenant,
        webhook_url, idempotency_key, digest,
    )  # fmt: skip
