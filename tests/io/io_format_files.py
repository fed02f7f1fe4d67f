"""Small files of every format, made with the peer libraries (laspy, trimesh, pypcd4, pye57,
ezdxf), so the tests read files geosmooth did not write."""

from __future__ import annotations

import io
import os
import tempfile
from typing import Any

import numpy as np


def las_bytes(point_format: int, *, compress: bool = False, n: int = 3000, seed: int = 0) -> bytes:
    """A LAS/LAZ file of the given point format with random values in every dimension."""
    import laspy

    rng = np.random.default_rng(seed)
    version = "1.4" if point_format >= 6 else "1.2"
    header = laspy.LasHeader(point_format=point_format, version=version)
    header.scales = np.array([0.001, 0.001, 0.01])
    header.offsets = np.array([650000.0, 5600000.0, 0.0])
    las = laspy.LasData(header)
    las.x = 650000 + rng.uniform(0, 200, n)
    las.y = 5600000 + rng.uniform(0, 100, n)
    las.z = rng.uniform(200, 260, n)
    for dim in las.point_format.dimensions:
        if dim.name in ("X", "Y", "Z"):
            continue
        kind = np.dtype(dim.dtype) if dim.dtype is not None else np.dtype(np.uint8)
        if dim.num_bits and dim.num_bits < 8 * kind.itemsize:
            las[dim.name] = rng.integers(0, 2**dim.num_bits, n)
        elif kind.kind == "f":
            las[dim.name] = rng.uniform(0, 1e5, n)
        else:
            info = np.iinfo(kind)
            las[dim.name] = rng.integers(max(info.min, -1000), min(info.max, 60000), n)
    out = io.BytesIO()
    las.write(out, do_compress=compress)
    return out.getvalue()


def mesh() -> Any:
    """A small closed trimesh (an icosphere with a bump)."""
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=2)
    m.vertices[0] *= 1.3
    return m


def stl_bytes(ascii_stl: bool = False) -> bytes:
    """STL from trimesh (binary with attribute words, or ASCII)."""
    m = mesh()
    if ascii_stl:
        return str(m.export(file_type="stl_ascii")).encode()
    data = bytearray(m.export(file_type="stl"))
    data[:80] = b"made by trimesh for the geosmooth tests".ljust(80, b" ")
    for i in range(len(m.faces)):  # non-zero attribute words, which must survive
        data[84 + 50 * i + 48 : 84 + 50 * i + 50] = (i % 65536).to_bytes(2, "little")
    return bytes(data)


def off_bytes(kind: str = "OFF") -> bytes:
    """OFF / COFF (vertex colours) / NOFF (normals) text."""
    m = mesh()
    rows = [f"{kind}", f"{len(m.vertices)} {len(m.faces)} 0"]
    for i, v in enumerate(m.vertices):
        extra = ""
        if kind == "COFF":
            extra = f" {i % 256} {(3 * i) % 256} {(7 * i) % 256} 255"
        elif kind == "NOFF":
            n = m.vertex_normals[i]
            extra = f" {n[0]:.6f} {n[1]:.6f} {n[2]:.6f}"
        rows.append(f"{v[0]:.6f} {v[1]:.6f} {v[2]:.6f}{extra}")
    rows += [f"3 {a} {b} {c}" for a, b, c in m.faces]
    return ("\n".join(rows) + "\n").encode()


def glb_bytes() -> bytes:
    """A GLB of a textured mesh (UVs) from trimesh."""
    import trimesh

    m = mesh()
    uv = np.column_stack([m.vertices[:, 0] * 0.5 + 0.5, m.vertices[:, 1] * 0.5 + 0.5])
    m.visual = trimesh.visual.TextureVisuals(uv=uv)
    return bytes(m.export(file_type="glb"))


def pcd_bytes(encoding: str, *, with_nan: bool = False, n: int = 500) -> bytes:
    """PCD x y z rgb label (pypcd4), optionally with NaN points (an organised cloud)."""
    import pypcd4

    rng = np.random.default_rng(3)
    xyz = rng.normal(size=(n, 3)).astype(np.float32)
    if with_nan:
        xyz[::7] = np.nan
    rgb = pypcd4.PointCloud.encode_rgb(rng.integers(0, 255, (n, 3)))
    data = np.column_stack([xyz, rgb.astype(np.float32), np.arange(n) % 9])
    cloud = pypcd4.PointCloud.from_xyzrgbl_points(data)
    out = io.BytesIO()
    cloud.save(out, encoding=pypcd4.Encoding(encoding))
    return out.getvalue()


def e57_bytes(n: int = 800) -> bytes:
    """One E57 scan with a pose, intensity, colours and some invalid points (pye57)."""
    import pye57

    rng = np.random.default_rng(5)
    xyz = rng.normal(size=(n, 3)) * 2.0
    invalid = np.zeros(n, np.int8)
    invalid[:20] = 1
    fd, path = tempfile.mkstemp(suffix=".e57")
    os.close(fd)
    os.unlink(path)
    try:
        e57 = pye57.E57(path, mode="w")
        e57.write_scan_raw(
            {
                "cartesianX": xyz[:, 0],
                "cartesianY": xyz[:, 1],
                "cartesianZ": xyz[:, 2],
                "intensity": rng.uniform(0, 1, n).astype(np.float32),
                "colorRed": rng.integers(0, 255, n).astype(np.uint8),
                "colorGreen": rng.integers(0, 255, n).astype(np.uint8),
                "colorBlue": rng.integers(0, 255, n).astype(np.uint8),
                "cartesianInvalidState": invalid,
            },
            name="scan A",
            rotation=np.array([0.9238795325, 0.0, 0.0, 0.3826834324]),
            translation=np.array([100.0, 200.0, 10.0]),
        )
        e57.close()
        with open(path, "rb") as fh:
            return fh.read()
    finally:
        os.unlink(path)


def dxf_bytes() -> bytes:
    """A DXF with an LWPOLYLINE, a 3D POLYLINE, two LINEs and an ARC that chain, and a TEXT."""
    import ezdxf

    doc = ezdxf.new("R2010")
    msp = doc.modelspace()
    msp.add_lwpolyline([(0, 0), (1, 0.1), (2, -0.1), (3, 0)], dxfattribs={"layer": "A"})
    msp.add_polyline3d([(0, 5, 0), (1, 6, 1), (2, 5, 2)], close=True)
    msp.add_line((10, 0), (11, 0), dxfattribs={"layer": "B"})
    msp.add_arc((11, 1), radius=1, start_angle=270, end_angle=360, dxfattribs={"layer": "B"})
    msp.add_line((12, 1), (12, 3), dxfattribs={"layer": "B"})
    msp.add_text("keep me")
    out = io.StringIO()
    doc.write(out)
    return out.getvalue().encode()
