"""Wavefront OBJ reading (``v``, ``vt``, ``vn``, ``f``, ``l``); writing is in :mod:`.obj.write`.

Reading
-------
* ``v x y z [w | r g b [a]]``: the point; extra columns are attributes (``w``, or ``red green
  blue [alpha]``, any other count ``v3``, ``v4``, ...) written back unchanged.
* ``f`` in every index form (``v``, ``v/vt``, ``v//vn``, ``v/vt/vn``), 1-based or negative
  (relative to the statements before); polygons are fan-triangulated for the engine. The file's
  own faces stay as they are in the file (they are copied on write).
* ``l i j k ...``: a polyline; one whose last index repeats its first is closed.
* Every other line (``vt``, ``g``, ``o``, ``s``, ``usemtl``, ``mtllib``, comments, ...) is kept:
  the file is written back line for line with new ``v`` lines (the input's digits) and
  recomputed (or dropped) ``vn`` lines (see :mod:`.obj.write`). Unknown statements are counted
  in the notes; leading ``#`` lines are the document's comments.

The file is read in bounded blocks of lines; errors name the line.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from service.io._shared.assemble import assemble
from service.io._shared.numfmt import Digits
from service.io._shared.text import NUMBER, line_blocks, shown, tokens_per_line
from service.io.document import GeometryDocument, Precision
from service.io.errors import FormatError
from service.io.formats.obj.faces import Faces
from service.io.source import Source

__all__ = ["ObjLayout", "read_obj"]

_IGNORED = {b"vt", b"vp", b"g", b"o", b"s", b"usemtl", b"mtllib", b"usemap", b"maplib"}
_KEYS = (b"v", b"vn", b"vt", b"f", b"l")
_KINDS = frozenset(_KEYS)
_EXTRA_NAMES = {1: ("w",), 3: ("red", "green", "blue"), 4: ("red", "green", "blue", "alpha")}


@dataclass(frozen=True, eq=False)
class ObjLayout:
    """An OBJ file as read: its bytes, where its ``v``/``vn`` lines are, its corner normals.

    Attributes
    ----------
    data : bytes
        The file.
    v_spans, vn_spans : ndarray of int, shape (k, 2)
        Byte span ``[start, end)`` of every ``v`` / ``vn`` line (without the newline).
    corners : ndarray of int, shape (m, 2) or None
        When the file has ``vn``: each face corner's 0-based vertex and normal index (``-1``:
        none), in file order; ``counts`` gives the corners of each face.
    counts : ndarray of int or None
        Corners per face.
    extra : tuple of str
        Attribute names of the extra ``v`` columns.
    uv : (corner_vt, face_counts, vt_spans) or None
        When every face corner has a ``vt``: each corner's 0-based ``vt`` index in file order,
        the corners of each face, and the byte span of every ``vt`` line (other formats' writers
        that hold texture coordinates read them from there, e.g. glTF).
    """

    data: bytes
    v_spans: NDArray[np.int64]
    vn_spans: NDArray[np.int64]
    corners: NDArray[np.int64] | None
    counts: NDArray[np.int64] | None
    extra: tuple[str, ...]
    uv: tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]] | None = None


@dataclass
class _Acc:
    """What the blocks collect."""

    v_rows: list[NDArray[np.float64]] = field(default_factory=list)
    v_spans: list[NDArray[np.int64]] = field(default_factory=list)
    vn_spans: list[NDArray[np.int64]] = field(default_factory=list)
    vt_spans: list[NDArray[np.int64]] = field(default_factory=list)
    faces: list[tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]] = field(
        default_factory=list
    )
    lines: list[tuple[NDArray[np.int64], NDArray[np.int64]]] = field(default_factory=list)
    nv: int = 0
    nvt: int = 0
    nvn: int = 0
    width: int | None = None
    digits: Digits | None = None
    comments: list[str] = field(default_factory=list)
    other: dict[str, int] = field(default_factory=dict)
    started: bool = False
    ragged: bool = False


def _fail(line: int, message: str) -> FormatError:
    return FormatError(f"line {line}: {message}", fmt="obj", line=line)


def _vertices(acc: _Acc, texts: list[bytes], numbers: list[int]) -> None:
    joined = b"\n".join(texts)
    widths = tokens_per_line(joined, len(texts))
    if np.any(widths < 3):
        i = int(np.flatnonzero(widths < 3)[0])
        raise _fail(numbers[i], f"a vertex needs 3 coordinates, found {int(widths[i])}")
    try:
        values: NDArray[np.float64] | None = np.array(joined.split(), dtype=np.float64)
    except ValueError:
        values = None
    if values is None or b"_" in joined:
        for text, number in zip(texts, numbers, strict=True):
            for tok in text.split():
                if not NUMBER.fullmatch(tok):
                    raise _fail(number, f"{shown(tok)} is not a number")
    assert values is not None
    if acc.width is None:
        acc.width = int(widths[0])
        acc.digits = Digits(acc.width)
    if not acc.ragged and np.any(widths != acc.width):
        acc.ragged = True  # extra columns differ between lines: keep the coordinates only
        acc.v_rows = [r[:, :3] for r in acc.v_rows]
        acc.width = 3
    if acc.ragged:
        starts = np.concatenate([[0], np.cumsum(widths)[:-1]])
        acc.v_rows.append(values[starts[:, None] + np.arange(3)])
        return
    assert acc.digits is not None
    table = values.reshape(len(texts), acc.width)
    acc.digits.update(joined, table)
    acc.v_rows.append(table)


def _corner_columns(
    texts: list[bytes], numbers: list[int], what: str
) -> tuple[NDArray[np.int64], NDArray[np.int64], int]:
    """Corner index columns (v[, vt[, vn]]) of index statements; 0 where a component is absent."""
    joined = b"\n".join(texts)
    counts = tokens_per_line(joined, len(texts))
    per_token = _slashes_per_token(joined)
    m = int(per_token[0]) + 1 if per_token.size else 1
    if per_token.size and (np.any(per_token != per_token[0]) or m > 3):
        return _slow_corners(texts, numbers, what).reshape(-1, 3), counts, 3
    spread = joined.replace(b"//", b"/0/").replace(b"/", b" ") if m > 1 else joined
    try:
        raw = np.array(spread.split(), dtype=np.int64)
        ok = raw.size == m * int(counts.sum()) and b"_" not in joined
    except (ValueError, OverflowError):
        ok = False
    if not ok:
        raw = _slow_corners(texts, numbers, what)
        m = 3
    return raw.reshape(-1, m), counts, m


def _slashes_per_token(joined: bytes) -> NDArray[np.int64]:
    """Number of ``/`` in each whitespace-separated token."""
    raw = np.frombuffer(joined, dtype=np.uint8)
    if raw.size == 0:
        return np.zeros(0, dtype=np.int64)
    space = (raw == 32) | (raw == 9) | (raw == 10) | (raw == 13) | (raw == 11) | (raw == 12)
    start = ~space
    start[1:] &= space[:-1]
    starts = np.flatnonzero(start)
    token_of_slash = np.searchsorted(starts, np.flatnonzero(raw == 47), side="right") - 1
    return np.bincount(token_of_slash, minlength=starts.size).astype(np.int64)


def _slow_corners(texts: list[bytes], numbers: list[int], what: str) -> NDArray[np.int64]:
    """Per-token parsing (mixed index forms, or to name the bad line)."""
    out: list[int] = []
    for text, number in zip(texts, numbers, strict=True):
        for tok in text.split():
            parts = tok.split(b"/")
            if len(parts) > 3 or not parts[0]:
                raise _fail(number, f"{shown(tok)} is not a vertex index")
            vals = []
            for part in (*parts, b"", b"")[:3]:
                try:
                    if b"_" in part:
                        raise ValueError
                    vals.append(int(part) if part else 0)
                except ValueError:
                    raise _fail(number, f"{shown(part)} is not a vertex index") from None
            out.extend(vals)
    return np.asarray(out, dtype=np.int64)


def _classify(
    block: bytes, lines: list[bytes]
) -> tuple[dict[bytes, list[int]], dict[int, bytes], NDArray[np.int64], NDArray[np.int64]]:
    """Line indices of each statement kind, texts where they are not ``line[2:]`` / ``[3:]``,
    and every line's byte span within ``block`` (vectorized; odd lines in Python)."""
    raw = np.frombuffer(block, dtype=np.uint8)
    nl = np.flatnonzero(raw == 10)
    starts = np.concatenate([[0], nl + 1])[: len(lines)].astype(np.int64)
    ends = starts + np.fromiter(map(len, lines), dtype=np.int64, count=len(lines))
    pad = np.concatenate([raw, np.zeros(3, np.uint8)])
    a, b, c = pad[starts], pad[starts + 1], pad[starts + 2]
    sep_b = (b == 32) | (b == 9)
    sep_c = (c == 32) | (c == 9)
    masks = {
        b"v": (a == 118) & sep_b,
        b"vt": (a == 118) & (b == 116) & sep_c,
        b"vn": (a == 118) & (b == 110) & sep_c,
        b"f": (a == 102) & sep_b,
        b"l": (a == 108) & sep_b,
    }
    rows: dict[bytes, list[int]] = {k: np.flatnonzero(m).tolist() for k, m in masks.items()}
    rows[b"#"] = np.flatnonzero(a == 35).tolist()
    rows[b"?"] = []
    known = np.logical_or.reduce(list(masks.values())) | (a == 35) | (starts == ends)
    texts: dict[int, bytes] = {}
    resorted = False
    for i in np.flatnonzero(~known).tolist():  # indented, blank-with-spaces or other statements
        stripped = lines[i].strip()
        if not stripped:
            continue
        parts = stripped.split(None, 1)
        kind = parts[0] if parts[0] in _KINDS else (b"#" if stripped[:1] == b"#" else b"?")
        rows[kind].append(i)
        texts[i] = parts[1] if len(parts) > 1 else b""
        resorted = resorted or kind in _KINDS
    if resorted:
        for k in _KINDS:
            rows[k].sort()
    cr = (ends > starts) & (pad[np.maximum(ends - 1, 0)] == 13)
    return rows, texts, starts, ends - cr


def _block(
    acc: _Acc,
    faces: Faces,
    polys: Faces,
    block: bytes,
    lines: list[bytes],
    offset: int,
    first: int,
) -> None:
    rows, texts, starts, ends = _classify(block, lines)
    starts, ends = starts + offset, ends + offset
    statement_rows = [r for k in _KEYS for r in rows[k][:1]] + rows[b"?"][:1]
    head_end = min(statement_rows, default=len(lines)) if not acc.started else -1
    for i in rows[b"#"]:
        if i >= head_end:
            break
        acc.comments.append(lines[i].strip()[1:].strip().decode("utf-8", errors="replace"))
    acc.started = acc.started or bool(statement_rows)
    for i in rows[b"?"]:
        word = lines[i].split(None, 1)[0]
        if word not in _IGNORED:
            key = word.decode("utf-8", errors="replace")[:20]
            acc.other[key] = acc.other.get(key, 0) + 1

    def text(r: list[int], skip: int) -> list[bytes]:
        if not texts:
            return [lines[i][skip:] for i in r]
        return [texts[i] if i in texts else lines[i][skip:] for i in r]

    if rows[b"v"]:
        vr = rows[b"v"]
        _vertices(acc, text(vr, 2), [first + i for i in vr])
        acc.v_spans.append(np.column_stack([starts[vr], ends[vr]]))
    for statement, spans in ((b"vn", acc.vn_spans), (b"vt", acc.vt_spans)):
        if rows[statement]:
            spans.append(np.column_stack([starts[rows[statement]], ends[rows[statement]]]))
    for kind, sink, what in ((b"f", faces, "face"), (b"l", polys, "polyline")):
        r = rows[kind]
        if not r:
            continue
        at = np.asarray(r)
        before = [
            acc.nv + np.searchsorted(np.asarray(rows[b"v"], dtype=np.int64), at),
            acc.nvt + np.searchsorted(np.asarray(rows[b"vt"], dtype=np.int64), at),
            acc.nvn + np.searchsorted(np.asarray(rows[b"vn"], dtype=np.int64), at),
        ]
        numbers = [first + i for i in r]
        sink.add(_corner_columns(text(r, 2), numbers, what), numbers, before, what)
    acc.nv += len(rows[b"v"])
    acc.nvt += len(rows[b"vt"])
    acc.nvn += len(rows[b"vn"])


def _scan(data: bytes) -> tuple[_Acc, Faces, Faces]:
    """Every line of ``data`` classified, block by block of complete lines: the vertices and
    other statements, the faces, the polylines (``l``)."""
    acc, faces, polys = _Acc(), Faces(), Faces()
    line = 1
    for block in line_blocks(data, 0):
        lines = block.data.split(b"\n")
        if block.data.endswith(b"\n"):
            lines.pop()
        _block(acc, faces, polys, block.data, lines, block.offset, line)
        line += block.data.count(b"\n")
    return acc, faces, polys


_Ints = NDArray[np.int64]


def _polygons(
    acc: _Acc, faces: Faces, totals: tuple[int, int, int], notes: list[str]
) -> tuple[
    tuple[_Ints, _Ints] | None, _Ints | None, _Ints | None, tuple[_Ints, _Ints, _Ints] | None
]:
    """The faces as ``(flat, counts)``, their counts, the ``(vertex, vn)`` index of every corner
    and the corners' texture coordinates (:attr:`ObjLayout.uv`; each ``None`` when absent)."""
    polygons: tuple[_Ints, _Ints] | None = None
    counts: _Ints | None = None
    corners: _Ints | None = None
    uv: tuple[_Ints, _Ints, _Ints] | None = None
    if faces.v:
        flat, counts, vn = faces.finish(totals, "face", notes)
        polygons = (flat, counts)
        corner_vt = faces.texture(acc.nvt)
        if corner_vt is not None:
            uv = (corner_vt, counts, np.concatenate(acc.vt_spans))
        if vn is not None and acc.nvn:
            corners = np.column_stack([flat, vn])
    return polygons, counts, corners, uv


def read_obj(source: Source, *, weld: bool = False) -> GeometryDocument:
    """Read an OBJ file.

    Raises
    ------
    FormatError
        Non-numeric tokens and indices out of range (with the line number), vertices with fewer
        than 3 coordinates, no ``v`` lines.
    """
    data = source.data()
    acc, faces, polys = _scan(data)
    notes = [f"ignored {k} OBJ {name!r} statements" for name, k in sorted(acc.other.items())]
    if acc.nv == 0:
        found = sorted(acc.other)
        hint = f" (found only unsupported statements: {', '.join(found)})" if found else ""
        raise FormatError(f"the file holds no points: no 'v' lines{hint}", fmt="obj")
    table = np.concatenate(acc.v_rows)
    totals = (acc.nv, acc.nvt, acc.nvn)
    polygons, counts, corners, uv = _polygons(acc, faces, totals, notes)
    polylines: list[tuple[NDArray[np.int64], bool]] = []
    if polys.v:
        flat_l, counts_l, _ = polys.finish(totals, "polyline", notes)
        polylines = [(p, False) for p in np.split(flat_l, np.cumsum(counts_l)[:-1])]
    assert acc.digits is not None and acc.width is not None
    specs = acc.digits.specs() if not acc.ragged else ("%r",) * 3
    if acc.ragged:
        notes.append("'v' lines have different numbers of values: extra columns dropped")
    extra = acc.width - 3
    names = _EXTRA_NAMES.get(extra, tuple(f"v{j}" for j in range(3, acc.width)))
    attributes = {n: table[:, 3 + j] for j, n in enumerate(names)} if extra else {}
    empty = np.zeros((0, 2), dtype=np.int64)
    layout = ObjLayout(
        data,
        np.concatenate(acc.v_spans),
        np.concatenate(acc.vn_spans) if acc.vn_spans else empty,
        corners,
        counts if corners is not None else None,
        tuple(names) if extra else (),
        uv,
    )
    precision = Precision("float64", specs[:3], dict(zip(names, specs[3:], strict=False)))
    doc = assemble(
        np.ascontiguousarray(table[:, :3]),
        fmt="obj",
        polygons=polygons,
        polylines=polylines,
        notes=notes,
        comments=acc.comments,
        weld=weld,
    )
    return doc.with_extras(attributes=attributes, precision=precision, layout=layout)
