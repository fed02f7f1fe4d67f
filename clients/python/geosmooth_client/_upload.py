"""The request of ``POST /v1/jobs``: any input as a re-sendable, interruptible multipart upload.

:class:`Upload` turns a path, bytes, a geometry mapping or a points array plus parameters into
the multipart form of ``POST /v1/jobs``; its file part is a :class:`TrackedFile`, which knows
whether the whole file went out and stops the upload when asked: Ctrl-C before the end of the
body leaves no job on the service, which never sees a complete request.
"""

from __future__ import annotations

import errno
import io
import json
import os
import threading
import uuid
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

__all__ = ["TrackedFile", "Upload", "UploadAborted", "params_dict"]


class UploadAborted(Exception):
    """Raised inside the upload when it is stopped before the end of the file."""


class TrackedFile(io.RawIOBase):
    """A readable file that knows whether it was read to the end, and can stop a read.

    Parameters
    ----------
    raw : binary file
        The data (an open file or a ``BytesIO``).
    """

    def __init__(self, raw: IO[bytes]) -> None:
        super().__init__()
        self._raw = raw
        self._lock = threading.Lock()
        self._stopped = False
        self.sent = False  # every byte of the file was handed to the connection

    def stop(self) -> bool:
        """Make the next read raise :class:`UploadAborted`; returns whether it was all sent.

        Atomic with :meth:`read`: when it returns ``False``, the end of the file is never
        read, so the request body is never complete and the service makes no job of it.
        """
        with self._lock:
            self._stopped = True
            return self.sent

    def readable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def fileno(self) -> int:  # lets httpx find the length (a Content-Length, not chunks)
        return self._raw.fileno()

    def seek(self, offset: int, whence: int = os.SEEK_SET) -> int:
        return self._raw.seek(offset, whence)

    def tell(self) -> int:
        return self._raw.tell()

    def read(self, size: int = -1) -> bytes:
        with self._lock:
            if self._stopped and not self.sent:
                raise UploadAborted("upload stopped")
            chunk = self._raw.read(size)
            if not chunk:
                self.sent = True
            return chunk

    def readinto(self, buffer: Any) -> int:  # pragma: no cover - httpx calls read()
        data = self.read(len(buffer))
        buffer[: len(data)] = data
        return len(data)

    def close(self) -> None:
        self._raw.close()
        super().close()


def _jsonable(value: Any) -> Any:
    """numpy arrays and scalars to lists and numbers (no numpy import needed)."""
    if hasattr(value, "tolist") and not isinstance(value, str | bytes):
        return value.tolist()
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    return value


def params_dict(params: Any, overrides: Mapping[str, Any]) -> dict[str, Any]:
    """Smoothing parameters as a JSON object: a mapping or a pydantic model, plus keywords.

    ``None`` values are left out (the service's defaults apply).
    """
    if params is None:
        base: dict[str, Any] = {}
    elif isinstance(params, Mapping):
        base = dict(params)
    elif hasattr(params, "model_dump"):
        base = params.model_dump(mode="json", exclude_unset=True)
    else:
        raise TypeError(f"params must be a mapping or a pydantic model, not {type(params)}")
    base.update(overrides)
    return {k: _jsonable(v) for k, v in base.items() if v is not None}


@dataclass(frozen=True)
class Upload:
    """One ``POST /v1/jobs`` multipart request, re-sendable (a retry opens the data again).

    Build it with :meth:`build`; :meth:`request` gives the keyword arguments of one attempt.
    """

    opener: Callable[[], IO[bytes]]
    filename: str
    form: dict[str, str]
    idempotency_key: str = field(default_factory=lambda: uuid.uuid4().hex)

    @classmethod
    def build(
        cls,
        source: Any,
        params: Mapping[str, Any],
        *,
        fmt: str | None = None,
        filename: str | None = None,
        weld: bool | None = None,
        webhook_url: str | None = None,
        idempotency_key: str | None = None,
    ) -> Upload:
        """Validate the input locally and prepare the form.

        Parameters
        ----------
        source : path, bytes, mapping or array_like
            A file path; the file's bytes (give ``fmt`` or a ``filename`` with an extension
            unless the service can tell the format from the content); a geometry in the JSON
            format's schema (``{"points": ..., "faces": ...}``, numpy arrays allowed); or the
            points themselves, an ``(n, s)`` array-like (a point cloud).
        """
        form = {"params": json.dumps(dict(params), allow_nan=False)}
        if isinstance(source, str | os.PathLike):
            path = Path(source)
            if not path.is_file():
                why = "Not a regular file" if path.exists() else "No such file or directory"
                raise OSError(errno.EINVAL if path.exists() else errno.ENOENT, why, str(path))
            opener: Callable[[], IO[bytes]] = lambda: path.open("rb")  # noqa: E731
            name = filename or path.name
        elif isinstance(source, bytes | bytearray | memoryview):
            data = bytes(source)
            opener = lambda: io.BytesIO(data)  # noqa: E731
            name = filename or (f"input.{fmt}" if fmt else "input")
        else:
            geometry = source if isinstance(source, Mapping) else {"points": source}
            text = json.dumps(_jsonable(geometry), allow_nan=False, separators=(",", ":"))
            data = text.encode("utf-8")
            opener = lambda: io.BytesIO(data)  # noqa: E731
            name, fmt = filename or "geometry.json", fmt or "json"
        if fmt:
            form["input_format"] = fmt
        if weld is not None:  # else the service's default for the format (STL, GLB: welded)
            form["weld"] = "true" if weld else "false"
        if webhook_url:
            form["webhook_url"] = webhook_url
        key = idempotency_key or uuid.uuid4().hex
        return cls(opener=opener, filename=name, form=form, idempotency_key=key)

    def request(self) -> tuple[TrackedFile, dict[str, Any]]:
        """The file part of one attempt and the ``httpx`` keyword arguments that send it."""
        body = TrackedFile(self.opener())
        kwargs = {
            "data": self.form,
            "files": {"file": (self.filename, body, "application/octet-stream")},
            "headers": {"Idempotency-Key": self.idempotency_key},
        }
        return body, kwargs
