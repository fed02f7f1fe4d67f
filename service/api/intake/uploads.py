"""Receiving a smoothing request: the body is streamed to a spool file, never held in memory.

``multipart/form-data`` (``file`` + ``params`` [+ ``format``, ``weld``, ``webhook_url``]) is
parsed while it streams in: the ``file`` part goes straight to a file under the spool directory,
the small parts (at most 64 KiB each) are kept as text. ``params`` may come as a form field *or*
as a JSON file part (Swagger UI, ``curl -F params=@p.json;type=application/json`` and httpx
send it that way). An ``application/json`` body (``{geometry, params, weld, webhook_url}``) is
spooled whole. Nothing is parsed here: the geometry and the JSON body are read in a worker
process (:mod:`service.api.intake.ingest`), so one upload can neither stall the event loop nor blow
up
the server's memory. Bytes are counted as they arrive by
:class:`service.api.http.limits.BodyLimitMiddleware`.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, Literal, cast

from python_multipart.exceptions import FormParserError
from python_multipart.multipart import MultipartParser, parse_options_header
from starlette.requests import Request

from service.api.errors import ApiProblem
from service.jobs.errors import storage_error

if TYPE_CHECKING:
    from python_multipart.multipart import MultipartCallbacks

__all__ = ["FIELDS", "Upload", "receive_upload"]

#: Small parts of a multipart upload besides ``file``.
FIELDS = ("params", "input_format", "format", "weld", "webhook_url")
_SMALL_PART = 64 * 1024


@dataclass
class Upload:
    """A received request, spooled.

    Attributes
    ----------
    kind : {"multipart", "json"}
        How the request came.
    path : Path or None
        The uploaded file (multipart) or the whole body (json); ``None`` if no file part came.
    size : int
        Bytes in ``path``.
    filename : str or None
        The file part's name (base name only).
    part_type : str or None
        The file part's ``Content-Type`` (without parameters).
    fields : dict
        Text of the small parts (``params``, ``format``, ``weld``, ``webhook_url``).
    """

    kind: Literal["multipart", "json"]
    path: Path | None = None
    size: int = 0
    filename: str | None = None
    part_type: str | None = None
    fields: dict[str, str] = field(default_factory=dict)

    def discard(self) -> None:
        """Remove the spool file (no error if it was moved away, e.g. into the job store)."""
        if self.path is not None:
            self.path.unlink(missing_ok=True)


def _invalid(field_name: str, detail: str, status: int = 422) -> ApiProblem:
    code = "invalid-request" if status == 422 else "malformed-request"
    return ApiProblem(
        status,
        detail,
        code=code,
        title="Invalid request" if status == 422 else None,
        field=field_name,
        errors=[{"field": field_name, "message": detail, "type": code}] if status == 422 else None,
    )


def _spool(spool_dir: Path, suffix: str) -> tuple[Path, IO[bytes]]:
    spool_dir.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(prefix="upload-", suffix=suffix, dir=spool_dir)
    return Path(name), os.fdopen(fd, "wb")


class _Parts:
    """Callbacks of python-multipart's streaming parser (one request)."""

    def __init__(self, upload: Upload, spool_dir: Path) -> None:
        self.upload = upload
        self.spool_dir = spool_dir
        self.headers: dict[bytes, bytes] = {}
        self.header_field = bytearray()
        self.header_value = bytearray()
        self.name: str | None = None
        self.text: bytearray | None = None
        self.sink: IO[bytes] | None = None
        self.ended = False

    def callbacks(self) -> dict[str, Any]:
        return {
            "on_part_begin": self.part_begin,
            "on_header_field": lambda d, s, e: self.header_field.extend(d[s:e]),
            "on_header_value": lambda d, s, e: self.header_value.extend(d[s:e]),
            "on_header_end": self.header_end,
            "on_headers_finished": self.headers_finished,
            "on_part_data": self.part_data,
            "on_part_end": self.part_end,
            "on_end": self.end,
        }

    def part_begin(self) -> None:
        self.headers, self.name, self.text = {}, None, None

    def header_end(self) -> None:
        self.headers[bytes(self.header_field).lower().strip()] = bytes(self.header_value).strip()
        self.header_field.clear()
        self.header_value.clear()

    def headers_finished(self) -> None:
        _, disposition = parse_options_header(self.headers.get(b"content-disposition"))
        name = disposition.get(b"name", b"").decode("utf-8", "replace")
        filename = disposition.get(b"filename")
        self.name = name
        if name == "file":
            if self.upload.path is not None:
                raise _invalid("file", "send exactly one file part named 'file'")
            base = (filename or b"").decode("utf-8", "replace").replace("\\", "/")
            self.upload.filename = base.rsplit("/", 1)[-1] or None
            ctype, _ = parse_options_header(self.headers.get(b"content-type"))
            self.upload.part_type = ctype.decode("latin-1") or None
            self.upload.path, self.sink = _spool(self.spool_dir, ".upload")
        elif name in FIELDS:
            if name in self.upload.fields:
                raise _invalid(name, f"the part {name!r} was sent twice")
            self.text = bytearray()
        else:
            shown = name or "(unnamed)"
            raise _invalid(
                shown, f"unknown form field {shown!r}; expected file, {', '.join(FIELDS)}"
            )

    def part_data(self, data: bytes, start: int, end: int) -> None:
        if self.sink is not None:
            self.sink.write(data[start:end])
            self.upload.size += end - start
        elif self.text is not None:
            self.text.extend(data[start:end])
            if len(self.text) > _SMALL_PART:
                raise _invalid(str(self.name), f"the part {self.name!r} exceeds 64 KiB", 413)

    def part_end(self) -> None:
        if self.sink is not None:
            self.sink.close()
            self.sink = None
        elif self.text is not None and self.name is not None:
            try:
                self.upload.fields[self.name] = self.text.decode("utf-8")
            except UnicodeDecodeError:
                raise _invalid(self.name, f"the part {self.name!r} is not UTF-8 text") from None
            self.text = None

    def end(self) -> None:
        self.ended = True

    def close(self) -> None:
        if self.sink is not None:
            self.sink.close()
            self.sink = None


async def _multipart(request: Request, boundary: bytes, spool_dir: Path) -> Upload:
    upload = Upload("multipart")
    parts = _Parts(upload, spool_dir)
    try:
        parser = MultipartParser(boundary, cast("MultipartCallbacks", parts.callbacks()))
        async for chunk in request.stream():
            if chunk:
                parser.write(chunk)
        parser.finalize()
        if not parts.ended:
            raise _invalid("body", "the multipart body ends before its closing boundary", 400)
        return upload
    except FormParserError as exc:
        upload.discard()
        raise _invalid("body", f"malformed multipart body: {exc}", 400) from None
    except BaseException as exc:
        upload.discard()
        _raise_storage(exc)
        raise
    finally:
        with contextlib.suppress(OSError):  # ENOSPC on the last flush: answered above
            parts.close()


def _raise_storage(exc: BaseException) -> None:
    """An ``OSError`` of the spool (ENOSPC, EDQUOT, EROFS ...) as its typed 507/503."""
    typed = storage_error(exc) if isinstance(exc, OSError) else None
    if typed is not None:
        raise typed from None


async def _json_body(request: Request, spool_dir: Path) -> Upload:
    upload = Upload("json")
    try:
        upload.path, sink = _spool(spool_dir, ".json")
        with sink:
            async for chunk in request.stream():
                sink.write(chunk)
                upload.size += len(chunk)
        return upload
    except BaseException as exc:
        upload.discard()
        _raise_storage(exc)
        raise


async def receive_upload(request: Request, spool_dir: Path) -> Upload:
    """Stream the request's body to ``spool_dir`` (see the module docstring).

    Raises
    ------
    ApiProblem
        415 for another content type, 400 for a malformed multipart body, 422 for unknown,
        repeated or missing parts, 413 for an oversized small part.
    StorageError
        507 when the spool is out of space (ENOSPC, EDQUOT), 503 when it cannot be written.
    """
    ctype, options = parse_options_header(request.headers.get("content-type"))
    media = ctype.decode("latin-1")
    if media == "multipart/form-data":
        boundary = options.get(b"boundary")
        if not boundary:
            raise _invalid("content-type", "multipart/form-data needs a boundary parameter", 400)
        upload = await _multipart(request, boundary, spool_dir)
        if upload.path is None:
            raise ApiProblem(
                422,
                "a file part named 'file' is required",
                code="missing-field",
                title="Invalid request",
                field="file",
                errors=[{"field": "file", "message": "required", "type": "missing"}],
            )
        return upload
    if media == "application/json" or media.endswith("+json"):
        return await _json_body(request, spool_dir)
    raise ApiProblem(
        415,
        f"unsupported content type {media or '(none)'!r}: send multipart/form-data"
        " (file, params[, format]) or application/json ({geometry, params})",
        code="unsupported-media-type",
        title="Unsupported Media Type",
        field="content-type",
    )
