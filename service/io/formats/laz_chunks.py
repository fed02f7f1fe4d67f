"""The LAZ chunk table, checked before lazrs reads it (issue 42).

lazrs allocates the table from its count without a check: a corrupted count made it allocate
52 GB and abort the process (SIGABRT, no Python exception). :func:`check_chunk_table` reads the
laszip VLR's chunk size and the table's header with plain ``struct`` first (called by
:func:`service.io.formats.las.open_points`, so both the ordinary and the streamed reader).
"""

from __future__ import annotations

import struct
from typing import BinaryIO

from service.io.errors import FormatError
from service.io.source import Source

__all__ = ["check_chunk_table"]

_LASZIP_VLR = (b"laszip encoded", 22204)
_VARIABLE_CHUNKS = 0xFFFFFFFF


def _laszip_chunk_size(fh: BinaryIO, header_size: int, n_vlrs: int) -> int | None:
    """The ``chunk_size`` of the laszip VLR (``None``: no such VLR, laspy will say so)."""
    pos = header_size
    for _ in range(n_vlrs):
        fh.seek(pos)
        head = fh.read(54)
        if len(head) < 54:
            return None
        length = struct.unpack_from("<H", head, 20)[0]
        if (head[2:18].rstrip(b"\0"), struct.unpack_from("<H", head, 18)[0]) == _LASZIP_VLR:
            data = fh.read(length)
            return struct.unpack_from("<I", data, 12)[0] if len(data) >= 16 else None
        pos += 54 + length
    return None


def check_chunk_table(source: Source, fmt: str) -> None:
    """A LAZ chunk table's count must fit the points and the file before lazrs reads it.

    lazrs allocates the table from its count (16 bytes an entry) without a check: a corrupted
    count made it allocate 42 GB and abort the process (SIGABRT, no Python exception). A table
    cannot hold more chunks than points, than bytes of the file, or (fixed-size chunks) than
    ``ceil(n / chunk_size)``; a chunk size of 0 is malformed.
    """
    head, size = source.head(255), source.size
    if not head[104] & 0x80:  # the point format's compression bit
        return
    n = struct.unpack_from("<I", head, 107)[0]
    if head[25] >= 4 and len(head) >= 255:
        n = max(n, struct.unpack_from("<Q", head, 247)[0])
    with source.open() as fh:
        header_size, offset, n_vlrs = struct.unpack_from("<HII", head, 94)
        chunk_size = _laszip_chunk_size(fh, header_size, n_vlrs)
        if chunk_size is None:
            return
        if chunk_size == 0:
            raise FormatError(f"{fmt.upper()}: the laszip VLR's chunk size is 0", fmt=fmt)
        fh.seek(offset)
        raw = fh.read(8)
        table = struct.unpack("<q", raw)[0] if len(raw) == 8 else -2
        if table == -1 and size >= 8:  # written at the end when the writer could not seek
            fh.seek(size - 8)
            table = struct.unpack("<q", fh.read(8))[0]
        if not offset + 8 <= table <= size - 8:
            return  # no table in the file: lazrs refuses it (an exception) or reads without
        fh.seek(table)
        count = struct.unpack("<II", fh.read(8))[1]
    limit = min(n, size)
    if chunk_size != _VARIABLE_CHUNKS:
        limit = min(limit, -(-n // chunk_size))
    if count > limit:
        raise FormatError(
            f"{fmt.upper()}: the chunk table declares {count} chunks, more than {limit}"
            f" ({n} points, {size} bytes, chunks of {chunk_size} points)",
            fmt=fmt,
        )
