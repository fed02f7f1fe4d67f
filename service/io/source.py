"""What a reader reads: :class:`Source`, the bytes of an upload or a path on disk.

Readers that parse bytes call :meth:`Source.data`; library-backed readers that stream (LAS/LAZ)
or need a real file (E57) use :meth:`Source.open` / :meth:`Source.as_path`, so a big file on disk
is never copied into memory whole.
"""

from __future__ import annotations

import contextlib
import io
import mmap
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

__all__ = ["UTF8_BOM", "Mapped", "Source", "mapped"]

#: The UTF-8 byte order mark, dropped from the start of text formats (:meth:`Source.without_bom`).
UTF8_BOM = b"\xef\xbb\xbf"


class Source:
    """The input of a reader: bytes, or a path read lazily."""

    def __init__(
        self, data: bytes | None = None, path: Path | None = None, name: str | None = None
    ) -> None:
        if (data is None) == (path is None):
            raise ValueError("a Source is either bytes or a path")
        self._data = data
        self.path = path
        self.name = name if name is not None else (path.name if path is not None else "")

    @classmethod
    def of(cls, source: bytes | bytearray | memoryview | str | os.PathLike[str] | Source) -> Source:
        """Wrap bytes, a path, or an existing Source."""
        if isinstance(source, Source):
            return source
        if isinstance(source, bytes | bytearray | memoryview):
            return cls(data=bytes(source))
        if isinstance(source, str | os.PathLike):
            return cls(path=Path(source))
        raise TypeError(f"source must be bytes or a path, got {type(source).__name__}")

    @property
    def size(self) -> int:
        """Size in bytes."""
        if self._data is not None:
            return len(self._data)
        assert self.path is not None
        return self.path.stat().st_size

    def data(self) -> bytes:
        """The whole content (a path is read once and kept)."""
        if self._data is None:
            assert self.path is not None
            self._data = self.path.read_bytes()
        return self._data

    def without_bom(self) -> Source:
        """The content without a leading UTF-8 byte order mark (``self`` when there is none).

        Text files saved by Windows editors start with ``EF BB BF``; a reader that took those
        bytes for content would misread the first line (an OBJ lost its first vertex).
        """
        if self.head(len(UTF8_BOM)) != UTF8_BOM:
            return self
        if self._data is not None:
            return Source(data=self._data[len(UTF8_BOM) :], name=self.name)
        assert self.path is not None
        with open(self.path, "rb") as fh:
            fh.seek(len(UTF8_BOM))
            return Source(data=fh.read(), name=self.name)

    def head(self, n: int = 4096) -> bytes:
        """The first ``n`` bytes."""
        if self._data is not None:
            return self._data[:n]
        assert self.path is not None
        with open(self.path, "rb") as fh:
            return fh.read(n)

    def open(self) -> BinaryIO:
        """A binary file object over the content."""
        if self._data is not None:
            return io.BytesIO(self._data)
        assert self.path is not None
        return open(self.path, "rb")

    @contextlib.contextmanager
    def as_path(self, suffix: str = "") -> Iterator[Path]:
        """A path to the content (a temporary file for bytes, removed afterwards)."""
        if self.path is not None:
            yield self.path
            return
        fd, name = tempfile.mkstemp(suffix=suffix, prefix="geosmooth-")
        try:
            with os.fdopen(fd, "wb") as fh:
                fh.write(self.data())
            yield Path(name)
        finally:
            with contextlib.suppress(OSError):
                os.unlink(name)


class Mapped:
    """A memory-mapped file seen as read-only bytes by the text parsers (``len``, slices,
    ``find``, ``rfind``, ``count``), so the streamed readers parse it with the ordinary readers'
    code without reading it into memory. ``.map`` is the mmap (numpy's ``frombuffer``)."""

    _STEP = 1 << 24

    def __init__(self, mm: mmap.mmap | bytes) -> None:
        self.map = mm

    def __len__(self) -> int:
        return len(self.map)

    def __getitem__(self, key: slice) -> bytes:
        return self.map[key]

    def find(self, sub: bytes, start: int = 0, end: int | None = None) -> int:
        return self.map.find(sub, start, len(self.map) if end is None else end)

    def rfind(self, sub: bytes, start: int = 0, end: int | None = None) -> int:
        return self.map.rfind(sub, start, len(self.map) if end is None else end)

    def count(self, sub: bytes, start: int = 0, end: int | None = None) -> int:
        """Occurrences of a one-byte ``sub`` (newlines), counted in 16 MiB windows."""
        stop = len(self.map) if end is None else min(end, len(self.map))
        return sum(
            self.map[at : min(at + self._STEP, stop)].count(sub)
            for at in range(max(start, 0), stop, self._STEP)
        )


@contextlib.contextmanager
def mapped(path: Path) -> Iterator[Mapped]:
    """A read-only memory map of ``path`` (an empty file: empty bytes)."""
    with open(path, "rb") as fh:
        if os.fstat(fh.fileno()).st_size == 0:
            yield Mapped(b"")
            return
        mm = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
        try:
            yield Mapped(mm)
        finally:
            with contextlib.suppress(BufferError):  # numpy views still alive: closed when freed
                mm.close()
