"""Binary PLY bodies (little- and big-endian), read with numpy structured dtypes.

Elements without list properties are one ``np.frombuffer``. Elements with lists take the same
fast path when every list has the length of the first entry's (e.g. all triangles; exact, since
each entry's count is then read at its true offset), otherwise one linear scan records where each
entry starts and the items are gathered with one vectorized index. Skipped elements are only
scanned for their length.
"""

from __future__ import annotations

import struct

import numpy as np
from numpy.typing import NDArray

from service.io.errors import FormatError
from service.io.ply_header import PlyElement, PlyHeader
from service.io.ply_types import ElementData

__all__ = ["read_binary_body"]


def _truncated(el: PlyElement, need: int, have: int) -> FormatError:
    return FormatError(
        f"binary PLY is truncated: element {el.name!r} ({el.count} entries) needs {need} more"
        f" bytes but only {max(have, 0)} remain (or the element counts do not match the data)",
        fmt="ply",
    )


def _binary_element(
    buf: bytes, pos: int, el: PlyElement, endian: str, want: bool
) -> tuple[ElementData | None, int]:
    """Read (or skip) one element of a binary body starting at ``pos``; return data, new pos."""
    props = el.properties
    if el.count == 0:
        return ({} if want else None), pos
    if not any(p.is_list for p in props):
        dt = np.dtype([(f"p{i}", endian + p.type) for i, p in enumerate(props)])
        need = el.count * dt.itemsize
        if pos + need > len(buf):
            raise _truncated(el, need, len(buf) - pos)
        if not want:
            return None, pos + need
        arr = np.frombuffer(buf, dtype=dt, count=el.count, offset=pos)
        return {p.name: arr[f"p{i}"] for i, p in enumerate(props)}, pos + need
    fast = _binary_uniform_lists(buf, pos, el, endian, want)
    if fast is not None:
        return fast
    return _binary_scan(buf, pos, el, endian, want)


def _binary_uniform_lists(
    buf: bytes, pos: int, el: PlyElement, endian: str, want: bool
) -> tuple[ElementData | None, int] | None:
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
    need = el.count * dt.itemsize
    arr = np.frombuffer(buf, dtype=dt, count=el.count, offset=pos)
    for i, k in lengths.items():
        if not np.all(arr[f"c{i}"] == k):
            return None
    if not want:
        return None, pos + need
    out: ElementData = {}
    for i, p in enumerate(el.properties):
        if i in lengths:
            k = lengths[i]
            items = arr[f"p{i}"].reshape(-1) if k else np.zeros(0, dtype=p.type)
            out[p.name] = (items, np.full(el.count, k, dtype=np.int64))
        else:
            out[p.name] = arr[f"p{i}"]
    return out, pos + need


def _binary_scan(
    buf: bytes, pos: int, el: PlyElement, endian: str, want: bool
) -> tuple[ElementData | None, int]:
    """General path: one linear pass recording where each property of each entry starts."""
    props = el.properties
    n = el.count
    size = len(buf)
    sizes = [np.dtype(p.type).itemsize for p in props]
    counters = [
        struct.Struct(("<" if endian == "<" else ">") + np.dtype(str(p.count_type)).char)
        if p.is_list
        else None
        for p in props
    ]
    starts: list[list[int]] = [[] for _ in props]
    counts: list[list[int]] = [[] for _ in props]
    single_u1 = len(props) == 1 and props[0].count_type == "u1"
    if single_u1:
        item = sizes[0]
        s0, c0 = starts[0], counts[0]
        for _ in range(n):
            if pos >= size:
                raise _truncated(el, 1, size - pos)
            k = buf[pos]
            s0.append(pos + 1)
            c0.append(k)
            pos += 1 + k * item
    else:
        for _ in range(n):
            for j in range(len(props)):
                counter = counters[j]
                if counter is None:
                    starts[j].append(pos)
                    pos += sizes[j]
                    continue
                if pos + counter.size > size:
                    raise _truncated(el, counter.size, size - pos)
                k = counter.unpack_from(buf, pos)[0]
                if k < 0:
                    raise FormatError(
                        f"element {el.name!r} has a negative list length {k}", fmt="ply"
                    )
                starts[j].append(pos + counter.size)
                counts[j].append(k)
                pos += counter.size + k * sizes[j]
    if pos > size:
        raise _truncated(el, pos - size, 0)
    if not want:
        return None, pos
    raw = np.frombuffer(buf, dtype=np.uint8)
    out: ElementData = {}
    for j, p in enumerate(props):
        st = np.asarray(starts[j], dtype=np.int64)
        dt = np.dtype(endian + p.type)
        if p.is_list:
            cnt = np.asarray(counts[j], dtype=np.int64)
            out[p.name] = (_gather(raw, st, cnt * dt.itemsize).view(dt), cnt)
        else:
            out[p.name] = _gather(raw, st, np.full(n, dt.itemsize, dtype=np.int64)).view(dt)
    return out, pos


def _gather(
    raw: NDArray[np.uint8], starts: NDArray[np.int64], nbytes: NDArray[np.int64]
) -> NDArray[np.uint8]:
    """Concatenate ``raw[starts[i] : starts[i] + nbytes[i]]`` for all ``i`` (vectorized)."""
    total = int(nbytes.sum())
    if total == 0:
        return np.zeros(0, dtype=np.uint8)
    offsets = np.concatenate([[0], np.cumsum(nbytes)[:-1]])
    idx = np.arange(total, dtype=np.int64) + np.repeat(starts - offsets, nbytes)
    return raw[idx].copy()


def read_binary_body(
    data: bytes, header: PlyHeader, notes: list[str], wanted: tuple[str, ...]
) -> dict[str, ElementData]:
    """Read the wanted elements of a binary body; note skipped ones."""
    endian = "<" if header.encoding == "binary_little_endian" else ">"
    pos = header.body_offset
    out: dict[str, ElementData] = {}
    for el in header.elements:
        want = el.name in wanted and el.name not in out
        got, pos = _binary_element(data, pos, el, endian, want)
        if got is not None:
            out[el.name] = got
        elif el.count:
            notes.append(f"skipped PLY element {el.name!r} ({el.count} entries)")
    trailing = data[pos:]
    if trailing.strip(b"\x00 \t\r\n"):
        raise FormatError(
            f"{len(trailing)} bytes after the last element (element counts do not match the data)",
            fmt="ply",
        )
    return out
