"""OBJ writing: the input file line for line, with new ``v`` and ``vn`` lines.

A document read from OBJ is written as its own file: every line that is not a ``v`` or ``vn``
statement (``vt``, ``f`` with its ``v/vt/vn`` structure, ``l``, groups, materials, comments) is
copied byte for byte; ``v`` lines get the new coordinates in the input's digits plus their extra
columns unchanged; ``vn`` lines are recomputed from the new geometry per corner (see
:func:`~service.io._shared.normals.corner_normals`), or dropped together with the ``/vn`` part of
the
faces (``normals="drop"``).

Other documents are written as ``v`` lines (2D points get ``z = 0``; ``red green blue``
attributes as the ``v x y z r g b`` colour extension, fractions in [0, 1]), ``vn`` (with
``f a//a``) when they carry normals, one ``vt`` per vertex for glTF's ``uv`` (with ``f a/a``),
``f`` triangles, one ``l`` per polyline (closed ones repeat their first index) and one ``l a b``
per standalone edge.
"""

from __future__ import annotations

import re
from typing import Any, BinaryIO

import numpy as np
from numpy.typing import NDArray

from service.io._shared.coords import as_xyz
from service.io._shared.normals import corner_normals
from service.io._shared.numfmt import F32, default_spec, format_column, write_rows
from service.io._shared.plain import PlainDocument
from service.io._shared.text import WRITTEN_BY, header_comments
from service.io.formats.obj.read import ObjLayout

__all__ = ["write_obj"]

_VN_TOKEN = re.compile(rb"(-?\d+)/(-?\d*)/-?\d+")
_F_LINE = re.compile(rb"(?m)^([ \t]*[fl][ \t][^\n]*)$")


def _normal_spec(plain: PlainDocument) -> str:
    mode = plain.options.precision
    return F32 if mode == "float32" else "%r" if mode == "float64" else "%.6g"


def _rows(prefix: str, columns: list[tuple[NDArray[Any], str]]) -> list[str]:
    cols = [format_column(v, spec) for v, spec in columns]
    return [prefix + " ".join(r) for r in zip(*cols, strict=True)]


def _strip_normals(text: bytes) -> bytes:
    def line(m: re.Match[bytes]) -> bytes:
        return _VN_TOKEN.sub(lambda t: t[1] + (b"/" + t[2] if t[2] else b""), m[1])

    return _F_LINE.sub(line, text)


def _after_leading_comments(data: bytes) -> int:
    """Offset of the first line that is neither blank nor a ``#`` comment."""
    pos = 0
    while pos < len(data):
        nl = data.find(b"\n", pos)
        end = len(data) if nl < 0 else nl + 1
        line = data[pos:end].strip()
        if line and not line.startswith(b"#"):
            break
        pos = end
    return pos


def _template(plain: PlainDocument, layout: ObjLayout, out: BinaryIO) -> None:
    data = layout.data
    pts = as_xyz(plain.points, "obj")
    specs = plain.coordinate_specs()
    v_cols = [(pts[:, j], specs[j]) for j in range(3)]
    v_cols += [(plain.attributes[n], plain.attribute_spec(n)) for n in layout.extra]
    mode = plain.options.normals
    replace_vn = mode == "drop" or (plain.moved and layout.corners is not None)
    normals = None
    if mode == "recompute" and replace_vn and layout.counts is not None:
        assert layout.corners is not None
        normals = corner_normals(
            pts, layout.corners[:, 0], layout.counts, layout.corners[:, 1], len(layout.vn_spans)
        )
    spans = [layout.v_spans]
    kinds = [np.zeros(len(layout.v_spans), dtype=np.int8)]
    if replace_vn and len(layout.vn_spans):
        spans.append(layout.vn_spans)
        kinds.append(np.ones(len(layout.vn_spans), dtype=np.int8))
    allspans = np.concatenate(spans)
    allkinds = np.concatenate(kinds)
    index = np.concatenate([np.arange(len(s)) for s in spans])
    order = np.argsort(allspans[:, 0], kind="stable")
    allspans, allkinds, index = allspans[order], allkinds[order], index[order]
    raw = np.frombuffer(data, dtype=np.uint8)
    gap = allspans[1:, 0] - allspans[:-1, 1]
    at = np.minimum(allspans[:-1, 1], raw.size - 1)
    joined = (gap == 1) | ((gap == 2) & (raw[at] == 13))
    breaks = np.flatnonzero(~joined | (allkinds[1:] != allkinds[:-1])) + 1
    bounds = np.concatenate([[0], breaks, [len(allspans)]])
    eol = "\r\n" if data.count(b"\r\n", 0, 4096) else "\n"
    drop = mode == "drop"
    pos = _after_leading_comments(data)
    out.write(data[:pos])
    if WRITTEN_BY not in plain.comments:
        out.write(f"# {WRITTEN_BY}{eol}".encode())
    for a, b in zip(bounds[:-1].tolist(), bounds[1:].tolist(), strict=True):
        start, end = int(allspans[a, 0]), int(allspans[b - 1, 1])
        between = data[pos:start]
        out.write(_strip_normals(between) if drop else between)
        idx = index[a:b]
        if allkinds[a] == 0:
            text = eol.join(_rows("v ", [(c[idx], s) for c, s in v_cols]))
        elif normals is not None:
            spec = _normal_spec(plain)
            text = eol.join(_rows("vn ", [(normals[idx, j], spec) for j in range(3)]))
        else:  # dropped vn lines vanish with their line break
            text = ""
            end = end + (len(eol) if data[end : end + len(eol)] == eol.encode() else 0)
        out.write(text.encode("ascii"))
        pos = end
    rest = data[pos:]
    out.write(_strip_normals(rest) if drop else rest)


def _colour_columns(attrs: dict[str, NDArray[Any]]) -> list[tuple[NDArray[Any], str]]:
    """``red green blue`` as the ``v x y z r g b`` extension's fractions in [0, 1] (8-bit
    channels / 255, 16-bit ones / 65535, fractions as they are), or nothing."""
    names = ("red", "green", "blue")
    if not all(c in attrs and attrs[c].ndim == 1 for c in names):
        return []
    rgb = np.column_stack([attrs[c] for c in names]).astype(np.float64)
    top = float(rgb.max()) if rgb.size else 0.0
    scale = 65535.0 if top > 255 else 255.0 if top > 1 or rgb.dtype.kind in "iu" else 1.0
    return [(rgb[:, j] / scale, "%.6g") for j in range(3)]


def _generated(plain: PlainDocument, out: BinaryIO) -> None:
    pts = as_xyz(plain.points, "obj")
    out.write("".join(f"# {c}\n" for c in header_comments(plain.comments)).encode("utf-8"))
    specs = plain.coordinate_specs()
    specs = specs + specs[-1:] if len(specs) == 2 else specs
    cols = [(pts[:, j], specs[j]) for j in range(3)] + _colour_columns(plain.attributes)
    write_rows(out, cols, prefix="v ")
    normals = plain.normals
    if normals is not None:
        spec = _normal_spec(plain)
        write_rows(out, [(np.asarray(normals[:, j]), spec) for j in range(3)], prefix="vn ")
    faces = plain.faces
    uv = plain.attributes.get("uv")
    uv = uv if uv is not None and uv.shape == (plain.n, 2) and faces is not None else None
    if uv is not None:  # glTF's texture coordinates: one ``vt`` per vertex
        write_rows(out, [(uv[:, j], default_spec(uv.dtype)) for j in range(2)], prefix="vt ")
    if faces is not None and len(faces):
        f = faces + 1
        corner = {(False, False): "{t}", (True, False): "{t}//{t}", (False, True): "{t}/{t}",
                  (True, True): "{t}/{t}/{t}"}[(normals is not None, uv is not None)]  # fmt: skip
        if corner != "{t}":
            cols = [(f[:, j], "%d") for j in range(3)]
            lines = _rows("f ", cols)
            lines = ["f " + " ".join(corner.format(t=t) for t in ln[2:].split()) for ln in lines]
            out.write(("\n".join(lines) + "\n").encode("ascii"))
        else:
            write_rows(out, [(f[:, j], "%d") for j in range(3)], prefix="f ")
    for pl in plain.polylines:
        idx = pl.indices + 1
        if pl.closed:
            idx = np.append(idx, idx[0])
        out.write(("l " + " ".join(map(str, idx.tolist())) + "\n").encode("ascii"))
    edges = plain.standalone_edges
    if edges is not None and len(edges):
        write_rows(out, [(edges[:, 0] + 1, "%d"), (edges[:, 1] + 1, "%d")], prefix="l ")


def write_obj(plain: PlainDocument, out: BinaryIO) -> None:
    """Write a plain document as OBJ (see the module docstring)."""
    layout = plain.layout
    if isinstance(layout, ObjLayout) and len(layout.v_spans) == plain.n:
        _template(plain, layout, out)
    else:
        _generated(plain, out)
