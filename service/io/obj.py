"""Wavefront OBJ reading and writing (``v``, ``f``, ``l``).

Reading
-------
* ``v x y z [w | r g b ...]``: the first three numbers are the point; extra columns are ignored.
* ``f`` in every index form (``v``, ``v/vt``, ``v//vn``, ``v/vt/vn``), 1-based or negative
  (relative to the vertices defined so far); polygons are fan-triangulated.
* ``l i j k ...``: a polyline. One whose last index repeats its first is a closed polyline and is
  stored once (``closed=True``). Its edges become ``geometry.edges``.
* ``vt``, ``vn``, ``vp``, ``g``, ``o``, ``s``, ``usemtl``, ``mtllib`` and comments are ignored;
  other statements (e.g. ``p``, free-form curves) are ignored and counted in the notes.
* Leading ``#`` lines are kept as the document's comments and written back.

Writing
-------
``v`` lines with every float64 in shortest round-trip form (``repr``), ``f`` triangles, one
``l`` per polyline (closed ones repeat their first index) and one ``l a b`` per standalone edge.
2D points get ``z = 0``; points with 1 or more than 3 coordinates cannot be written as OBJ.
"""

from __future__ import annotations

import re

import numpy as np
from numpy.typing import NDArray

from service.io.assemble import assemble
from service.io.coords import as_xyz
from service.io.document import GeometryDocument
from service.io.errors import FormatError
from service.io.text import (
    format_rows,
    header_comments,
    numeric_block,
    shown,
    tokens_per_line,
)

__all__ = ["read_obj", "write_obj"]

_IGNORED = {b"vt", b"vn", b"vp", b"g", b"o", b"s", b"usemtl", b"mtllib", b"usemap", b"maplib"}
_SLASH = re.compile(rb"/\S*")
_FAST_HEADS = {b"v ", b"f ", b"l ", b"vt", b"vn", b""}


class _Statements:
    """Lines of one statement type: their text after the keyword, line numbers, context."""

    def __init__(self, text: list[bytes], rows: NDArray[np.int64], nv_before: NDArray[np.int64]):
        self.text = text
        self.numbers = (rows + 1).tolist()
        self.nv_before = nv_before

    def __len__(self) -> int:
        return len(self.text)


def _vertices(v: _Statements) -> NDArray[np.float64]:
    flat = numeric_block(v.text, v.numbers, None, fmt="obj", what="a vertex")
    widths = tokens_per_line(b"\n".join(v.text), len(v.text))
    if np.any(widths < 3):
        bad = int(np.flatnonzero(widths < 3)[0])
        line = v.numbers[bad]
        raise FormatError(
            f"line {line}: a vertex needs 3 coordinates, found {int(widths[bad])}",
            fmt="obj",
            line=line,
        )
    if widths.min() == widths.max():
        return flat.reshape(len(v.text), int(widths[0]))[:, :3].copy()
    starts = np.concatenate([[0], np.cumsum(widths)[:-1]])
    return flat[starts[:, None] + np.arange(3)]


def _indices(st: _Statements, nv: int, what: str) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Parse index statements (``f`` or ``l``): 0-based flat indices and per-line counts."""
    joined = _SLASH.sub(b"", b"\n".join(st.text))
    counts = tokens_per_line(joined, len(st.text))
    try:
        raw = np.array(joined.split(), dtype=np.int64)
    except (ValueError, OverflowError):
        for text, number in zip(joined.split(b"\n"), st.numbers, strict=True):
            for tok in text.split():
                try:
                    int(tok)
                except ValueError:
                    raise FormatError(
                        f"line {number}: {shown(tok)} is not a vertex index",
                        fmt="obj",
                        line=number,
                    ) from None
        raise FormatError(f"could not parse the {what} indices", fmt="obj") from None
    before = np.repeat(st.nv_before, counts)
    flat = np.where(raw > 0, raw - 1, before + raw)
    bad = (raw == 0) | (flat < 0) | (flat >= nv)
    if bad.any():
        pos = int(np.flatnonzero(bad)[0])
        row = int(np.searchsorted(np.cumsum(counts), pos, side="right"))
        line = st.numbers[row]
        if raw[pos] == 0:
            msg = f"line {line}: index 0 is not valid (OBJ indices start at 1)"
        elif raw[pos] < 0:
            msg = (
                f"line {line}: {what} refers to relative vertex {int(raw[pos])} but only"
                f" {int(before[pos])} vertices precede it"
            )
        else:
            msg = (
                f"line {line}: {what} refers to vertex {int(raw[pos])}"
                f" but the file has {nv} vertices"
            )
        raise FormatError(msg, fmt="obj", line=line)
    return flat, counts


class _Scan:
    """One pass over the lines: rows of ``v``/``f``/``l`` statements, comments, the rest."""

    def __init__(self, lines: list[bytes]) -> None:
        heads = [line[:2] for line in lines]
        self.rows: dict[bytes, list[int]] = {
            b"v": [i for i, h in enumerate(heads) if h == b"v "],
            b"f": [i for i, h in enumerate(heads) if h == b"f "],
            b"l": [i for i, h in enumerate(heads) if h == b"l "],
        }
        self.texts: dict[int, bytes] = {}  # statement text when it is not line[2:]
        self.comments: list[tuple[int, str]] = []
        self.other: dict[str, int] = {}
        self.first_statement = min((r[0] for r in self.rows.values() if r), default=len(lines))
        resorted = False
        for i, h in enumerate(heads):
            if h in _FAST_HEADS:
                continue
            stripped = lines[i].strip()
            if not stripped:
                continue
            if stripped[:1] == b"#":
                self.comments.append((i, stripped[1:].strip().decode("utf-8", errors="replace")))
                continue
            self.first_statement = min(self.first_statement, i)
            parts = stripped.split(None, 1)
            key = parts[0]
            if key in self.rows:
                self.rows[key].append(i)
                self.texts[i] = parts[1] if len(parts) > 1 else b""
                resorted = True
            elif key not in _IGNORED:
                name = key.decode("utf-8", errors="replace")[:20]
                self.other[name] = self.other.get(name, 0) + 1
        if resorted:
            for rows in self.rows.values():
                rows.sort()
        self.lines = lines

    def statements(self, key: bytes) -> _Statements:
        rows = self.rows[key]
        texts, lines = self.texts, self.lines
        if texts:
            text = [texts[i] if i in texts else lines[i][2:] for i in rows]
        else:
            text = [lines[i][2:] for i in rows]
        arr = np.asarray(rows, dtype=np.int64)
        before = np.searchsorted(np.asarray(self.rows[b"v"], dtype=np.int64), arr)
        return _Statements(text, arr, before.astype(np.int64))


def read_obj(data: bytes, *, weld: bool = False) -> GeometryDocument:
    """Read an OBJ file from bytes.

    Raises
    ------
    FormatError
        Non-numeric tokens (with the line number), vertices with fewer than 3 coordinates,
        indices out of range, no ``v`` lines.
    """
    scan = _Scan(data.split(b"\n"))
    comments = [text for i, text in scan.comments if i < scan.first_statement]
    notes = [f"ignored {k} OBJ {name!r} statements" for name, k in sorted(scan.other.items())]
    nv = len(scan.rows[b"v"])
    if nv == 0:
        found = sorted(scan.other)
        hint = f" (found only unsupported statements: {', '.join(found)})" if found else ""
        raise FormatError(f"the file holds no points: no 'v' lines{hint}", fmt="obj")
    points = _vertices(scan.statements(b"v"))
    polygons = _indices(scan.statements(b"f"), nv, "face") if scan.rows[b"f"] else None
    polylines: list[tuple[NDArray[np.int64], bool]] = []
    if scan.rows[b"l"]:
        flat, counts = _indices(scan.statements(b"l"), nv, "polyline")
        polylines = [(p, False) for p in np.split(flat, np.cumsum(counts)[:-1])]
    return assemble(
        points,
        fmt="obj",
        polygons=polygons,
        polylines=polylines,
        notes=notes,
        comments=comments,
        weld=weld,
    )


def write_obj(doc: GeometryDocument, points: NDArray[np.float64] | None = None) -> bytes:
    """Write a document as OBJ text."""
    pts = as_xyz(doc.output_points(points), "obj")
    out = [f"# {c}\n" for c in header_comments(doc.comments)]
    out.append(format_rows(pts, prefix="v "))
    faces = doc.output_faces()
    if faces is not None and len(faces):
        out.append(format_rows(faces + 1, prefix="f "))
    for pl in doc.output_polylines():
        idx = pl.indices + 1
        if pl.closed:
            idx = np.append(idx, idx[0])
        out.append("l " + " ".join(map(str, idx.tolist())) + "\n")
    edges = doc.output_standalone_edges()
    if edges is not None and len(edges):
        out.append(format_rows(edges + 1, prefix="l "))
    return "".join(out).encode("utf-8")
