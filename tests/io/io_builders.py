"""Builders of small test files (imported by the io tests)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def ply_bytes(
    encoding: str,
    vertex_props: Sequence[tuple[str, str]],
    vertices: np.ndarray,
    faces: Sequence[Sequence[int]] | None = None,
    *,
    face_types: tuple[str, str] = ("uchar", "int"),
    face_name: str = "vertex_indices",
    extra_header: Sequence[str] = (),
    extra_elements: Sequence[tuple[str, str, Sequence[Sequence[int]]]] = (),
) -> bytes:
    """Build a small PLY file.

    ``vertex_props`` are (type, name) pairs; ``extra_elements`` are (name, list-declaration,
    lists) written after the faces, e.g. ``("range_grid", "list uchar int vertex_indices", ...)``.
    """
    head = ["ply", f"format {encoding} 1.0", *extra_header, f"element vertex {len(vertices)}"]
    head += [f"property {t} {name}" for t, name in vertex_props]
    if faces is not None:
        head += [
            f"element face {len(faces)}",
            f"property list {face_types[0]} {face_types[1]} {face_name}",
        ]
    for name, decl, lists in extra_elements:
        head += [f"element {name} {len(lists)}", f"property {decl}"]
    head.append("end_header")
    out = ("\n".join(head) + "\n").encode()
    if encoding == "ascii":
        rows = [" ".join(repr(v) for v in row) for row in np.asarray(vertices).tolist()]
        rows += [" ".join(map(str, [len(f), *f])) for f in faces or []]
        for _, _, lists in extra_elements:
            rows += [" ".join(map(str, [len(f), *f])) for f in lists]
        return out + ("\n".join(rows) + "\n").encode()
    e = "<" if encoding == "binary_little_endian" else ">"
    codes = {
        "float": "f4",
        "double": "f8",
        "uchar": "u1",
        "int": "i4",
        "uint": "u4",
        "float32": "f4",
        "uint8": "u1",
        "int32": "i4",
    }
    dt = np.dtype([(name, e + codes[t]) for t, name in vertex_props])
    rec = np.zeros(len(vertices), dtype=dt)
    for i, (_, name) in enumerate(vertex_props):
        rec[name] = np.asarray(vertices)[:, i]
    chunks = [out, rec.tobytes()]
    for lists, (ct, it) in [(faces or [], face_types)] + [
        (lists, (decl.split()[1], decl.split()[2])) for _, decl, lists in extra_elements
    ]:
        cdt, idt = np.dtype(e + codes[ct]), np.dtype(e + codes[it])
        for f in lists:
            chunks.append(np.array([len(f)], dtype=cdt).tobytes())
            chunks.append(np.array(f, dtype=idt).tobytes())
    return b"".join(chunks)
