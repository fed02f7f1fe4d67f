"""Binary PLY bodies (little- and big-endian), read with numpy structured dtypes.

Elements without list properties are one ``np.frombuffer`` (a view, no copy). Elements with lists
take the same path when every list has the length of the first entry's (e.g. all triangles:
exact, since each entry's count is then read at its true offset). Otherwise one linear scan reads
the list lengths only (stored in the file's count type, so at most the element's own size), runs
of equal lengths are skipped at numpy speed, and entry offsets are rebuilt from the lengths in
blocks when the values are gathered: memory stays within the element's size plus its values.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from service.io.errors import FormatError
from service.io.formats.ply.header import PlyElement, PlyHeader
from service.io.formats.ply.model import ElementData

__all__ = ["read_binary_body"]

_GATHER = 1 << 16


def _truncated(el: PlyElement, need: int, have: int) -> FormatError:
    return FormatError(
        f"binary PLY is truncated: element {el.name!r} ({el.count} entries) needs {need} more"
        f" bytes but only {max(have, 0)} remain (or the element counts do not match the data)",
        fmt="ply",
    )


def _binary_element(buf: bytes, pos: int, el: PlyElement, endian: str) -> tuple[ElementData, int]:
    """Read one element of a binary body starting at ``pos``; return its data and the new pos."""
    props = el.properties
    if el.count == 0:
        return {}, pos
    if not any(p.is_list for p in props):
        dt = np.dtype([(f"p{i}", endian + p.type) for i, p in enumerate(props)])
        need = el.count * dt.itemsize
        if pos + need > len(buf):
            raise _truncated(el, need, len(buf) - pos)
        arr = np.frombuffer(buf, dtype=dt, count=el.count, offset=pos)
        return {p.name: arr[f"p{i}"] for i, p in enumerate(props)}, pos + need
    fast = _binary_uniform_lists(buf, pos, el, endian)
    if fast is not None:
        return fast
    return _binary_scan(buf, pos, el, endian)


def _binary_uniform_lists(
    buf: bytes, pos: int, el: PlyElement, endian: str
) -> tuple[ElementData, int] | None:
    """Fast path: every list has the length it has in the first entry. ``None`` if not."""
    fields: list[tuple[str, str] | tuple[str, str, tuple[int]]] = []
    lengths: dict[int, int] = {}
    p0 = pos
    for i, p in enumerate(el.properties):
        if p.is_list:
            cdt = np.dtype(endian + str(p.count_type))
            if p0 + cdt.itemsize > len(buf):
                raise _truncated(el, cdt.itemsize, len(buf) - p0)
            k = int(np.frombuffer(buf, dtype=cdt, count=1, offset=p0)[0])
            if k < 0 or p0 + k > len(buf):
                return None  # the general path reports it
            lengths[i] = k
            fields.append((f"c{i}", cdt.str))
            if k > 0:
                fields.append((f"p{i}", endian + p.type, (k,)))
            p0 += cdt.itemsize + k * np.dtype(p.type).itemsize
        else:
            fields.append((f"p{i}", endian + p.type))
            p0 += np.dtype(p.type).itemsize
    if pos + el.count * (p0 - pos) > len(buf):
        return None
    dt = np.dtype(fields)
    arr = np.frombuffer(buf, dtype=dt, count=el.count, offset=pos)
    for i, k in lengths.items():
        if not np.all(arr[f"c{i}"] == k):
            return None
    out: ElementData = {}
    for i, p in enumerate(el.properties):
        if i in lengths:
            k = lengths[i]
            # (count, k) view of the input: no copy (readers reshape, or use it as faces)
            items = arr[f"p{i}"] if k else np.zeros((el.count, 0), dtype=endian + p.type)
            out[p.name] = (items, np.full(el.count, k, dtype=np.uint8 if k < 256 else np.int64))
        else:
            out[p.name] = arr[f"p{i}"]
    return out, pos + el.count * dt.itemsize


def _scan_lengths(
    buf: bytes, pos: int, el: PlyElement, endian: str
) -> tuple[list[NDArray[np.integer]], int]:
    """One pass over the entries: the length of every list, in the file's count type."""
    props = el.properties
    raw = np.frombuffer(buf, dtype=np.uint8)
    size = len(buf)
    sizes = [np.dtype(p.type).itemsize for p in props]
    cdts = [np.dtype(endian + str(p.count_type)) if p.is_list else None for p in props]
    lengths = [
        np.zeros(el.count, dtype=c.newbyteorder("=")) if c is not None else None for c in cdts
    ]
    first = lengths[0]
    if len(props) == 1 and first is not None and first.dtype == np.uint8:
        return [first], _scan_u1(buf, raw, pos, el, first, sizes[0])
    for i in range(el.count):
        for j, cdt in enumerate(cdts):
            column = lengths[j]
            if cdt is None or column is None:
                pos += sizes[j]
                continue
            if pos + cdt.itemsize > size:
                raise _truncated(el, cdt.itemsize, size - pos)
            k = int(np.frombuffer(buf, dtype=cdt, count=1, offset=pos)[0])
            if k < 0:
                raise FormatError(f"element {el.name!r} has a negative list length {k}", fmt="ply")
            column[i] = k
            pos += cdt.itemsize + k * sizes[j]
    if pos > size:
        raise _truncated(el, pos - size, 0)
    return [x if x is not None else np.zeros(0, np.uint8) for x in lengths], pos


def _scan_u1(
    buf: bytes, raw: NDArray[np.uint8], pos: int, el: PlyElement, out: NDArray[np.uint8], item: int
) -> int:
    """Lengths of a single ``list uchar ...`` property; runs of equal lengths are skipped."""
    size = len(buf)
    i = same = 0
    prev = -1
    while i < el.count:
        if pos >= size:
            raise _truncated(el, 1, size - pos)
        k = buf[pos]
        out[i] = k
        pos += 1 + k * item
        i += 1
        same = same + 1 if k == prev else 0
        prev = k
        if same >= 8:  # a run of equal lengths: skip it with one strided look
            stride = 1 + k * item
            room = min(el.count - i, max((size - pos) // stride, 0), 1 << 20)
            run = raw[pos : pos + room * stride : stride][:room]
            differs = run != k
            r = int(np.argmax(differs)) if differs.any() else int(run.size)
            out[i : i + r] = k
            pos += r * stride
            i += r
            same = 0
    if pos > size:
        raise _truncated(el, pos - size, 0)
    return pos


def _entry_sizes(
    lengths: list[NDArray[Any]],
    sizes: list[int],
    csizes: list[int],
    el: PlyElement,
    a: int,
    b: int,
) -> NDArray[np.int64]:
    """Byte size of entries ``a:b``."""
    out = np.zeros(b - a, dtype=np.int64)
    for j, p in enumerate(el.properties):
        if p.is_list:
            out += csizes[j] + lengths[j][a:b].astype(np.int64) * sizes[j]
        else:
            out += sizes[j]
    return out


def _binary_scan(buf: bytes, pos: int, el: PlyElement, endian: str) -> tuple[ElementData, int]:
    """General path: list lengths first, then every property gathered block by block.

    Blocks hold at most 65536 entries and about 4 MiB, so no array of the element's size other
    than its lengths (in the file's count type) and its values is ever allocated.
    """
    props = el.properties
    lengths, end = _scan_lengths(buf, pos, el, endian)
    raw = np.frombuffer(buf, dtype=np.uint8)
    sizes = [np.dtype(p.type).itemsize for p in props]
    csizes = [np.dtype(str(p.count_type)).itemsize if p.is_list else 0 for p in props]
    total = [
        int(lengths[j].sum(dtype=np.int64)) * sizes[j] if p.is_list else el.count * sizes[j]
        for j, p in enumerate(props)
    ]
    parts = [np.empty(t, dtype=np.uint8) for t in total]
    filled = [0] * len(props)
    at, s = pos, 0
    while s < el.count:
        sz = _entry_sizes(lengths, sizes, csizes, el, s, min(s + _GATHER, el.count))
        cum = np.cumsum(sz)
        k = max(int(np.searchsorted(cum, 1 << 22, side="right")), 1)
        sz = sz[:k]
        starts = at + np.concatenate([[0], cum[: k - 1]])
        within = np.zeros(k, dtype=np.int64)
        for j, p in enumerate(props):
            if p.is_list:
                nb = lengths[j][s : s + k].astype(np.int64) * sizes[j]
                got = _gather(raw, starts + within + csizes[j], nb)
                within += csizes[j] + nb
            else:
                got = _gather(raw, starts + within, np.full(k, sizes[j]))
                within += sizes[j]
            parts[j][filled[j] : filled[j] + got.size] = got
            filled[j] += got.size
        at += int(cum[k - 1])
        s += k
    out: ElementData = {}
    for j, p in enumerate(props):
        dt = np.dtype(endian + p.type)
        values = parts[j].view(dt)
        out[p.name] = (values, lengths[j]) if p.is_list else values
    return out, end


def _gather(
    raw: NDArray[np.uint8], starts: NDArray[np.int64], nbytes: NDArray[np.int64]
) -> NDArray[np.uint8]:
    """Concatenate ``raw[starts[i] : starts[i] + nbytes[i]]`` for all ``i`` (one block)."""
    t = int(nbytes.sum())
    if t == 0:
        return np.zeros(0, dtype=np.uint8)
    offsets = np.concatenate([[0], np.cumsum(nbytes)[:-1]])
    idx = np.arange(t, dtype=np.int64) + np.repeat(starts - offsets, nbytes)
    return raw[idx]


def read_binary_body(data: bytes, header: PlyHeader) -> list[ElementData]:
    """Read every element of a binary body, in header order."""
    endian = "<" if header.encoding == "binary_little_endian" else ">"
    pos = header.body_offset
    out: list[ElementData] = []
    for el in header.elements:
        got, pos = _binary_element(data, pos, el, endian)
        out.append(got)
    trailing = data[pos:]
    if trailing.strip(b"\x00 \t\r\n"):
        raise FormatError(
            f"{len(trailing)} bytes after the last element (element counts do not match the data)",
            fmt="ply",
        )
    return out
