"""Parsing memory stays a small multiple of the input (issue 15 item 1, parser side).

``tracemalloc`` sees numpy's buffers; the input bytes are allocated before tracing starts, so
the traced peak is what reading adds. Crafted inputs (one byte per PLY face, which took ~88x
before): input + additions <= 3x the input. Real data: additions <= the engine's own arrays
(float64 points and int64 triangles, which a binary mesh needs at ~2x its size; Geometry makes
its own int64 copy of the faces) + twice the input (the element data kept for writing back, and
the triangles before that copy) + 16 MB of blocks.
"""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from service.io import read_geometry


def _added_peak(data: bytes, fmt: str) -> float:
    tracemalloc.start()
    try:
        read_geometry(data, fmt, weld=False)  # the parser's cost (crafted vertices coincide)
        return tracemalloc.get_traced_memory()[1] / len(data)
    finally:
        tracemalloc.stop()


def _engine_bound(data: bytes, fmt: str) -> float:
    """(engine arrays + 2 x input + 16 MB) / input, for the same data."""
    g = read_geometry(data, fmt, weld=False).geometry
    engine = g.points.nbytes + (g.faces.nbytes if g.faces is not None else 0)
    return (engine + 2 * len(data) + 16e6) / len(data)


def _ply_head(encoding: str, faces: int) -> bytes:
    return (
        f"ply\nformat {encoding} 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        f"property float z\nelement face {faces}\nproperty list uchar int vertex_indices\n"
        "end_header\n"
    ).encode()


def test_crafted_binary_ply_of_empty_lists() -> None:
    # one byte per face: the old reader kept two Python ints per face (~88x)
    k = 32_000_000
    data = _ply_head("binary_little_endian", k) + np.zeros(9, "<f4").tobytes() + b"\0" * k
    assert 1 + _added_peak(data, "ply") <= 3.0


def test_crafted_ascii_ply_of_empty_lists() -> None:
    k = 16_000_000
    data = _ply_head("ascii", k) + b"0 0 0\n" * 3 + b"0\n" * k
    assert 1 + _added_peak(data, "ply") <= 3.0


def test_xyz_of_six_decimals() -> None:
    pts = np.random.default_rng(0).normal(size=(300_000, 3))
    data = ("\n".join(f"{a:.6f} {b:.6f} {c:.6f}" for a, b, c in pts.tolist()) + "\n").encode()
    assert _added_peak(data, "xyz") <= _engine_bound(data, "xyz")


@pytest.mark.parametrize("encoding", ["binary_little_endian", "ascii"])
def test_mixed_polygons(encoding: str) -> None:
    k = 400_000
    head = _ply_head(encoding, k)
    if encoding == "ascii":
        body = b"0 0 0\n1 0 0\n0 1 0\n" + b"3 0 1 2\n4 0 1 2 0\n" * (k // 2)
    else:
        tri = b"\x03" + np.array([0, 1, 2], "<i4").tobytes()
        quad = b"\x04" + np.array([0, 1, 2, 0], "<i4").tobytes()
        body = np.zeros(9, "<f4").tobytes() + (tri + quad) * (k // 2)
    assert _added_peak(head + body, "ply") <= _engine_bound(head + body, "ply")
