"""Streamed files of tiled runs (service.io.stream): every attribute survives, the coordinates
are the tiled solve's, through the CLI."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from service.core import Geometry, SmoothingParams, smooth
from service.io.stream import read_coordinates, rewrite, streamable
from tests.core.tiles.terrain import terrain_cloud, terrain_mesh

REPO = Path(__file__).resolve().parents[3]
PARAMS = SmoothingParams(tau=40.0, tile_points=3000)


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    exe = Path(sys.executable).with_name("geosmooth")
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.run([str(exe), "smooth", *args, "-q"], capture_output=True, text=True,
                          env=env, timeout=600, check=False)  # fmt: skip


def _las(path: Path, P: np.ndarray, compress: bool = False) -> None:
    import laspy

    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.array([1000.0, 2000.0, 0.0])
    header.add_extra_dim(laspy.ExtraBytesParams(name="reflectance", type=np.float32))
    las = laspy.LasData(header)
    rng = np.random.default_rng(2)
    las.x, las.y, las.z = P[:, 0] + 1000, P[:, 1] + 2000, P[:, 2]
    n = P.shape[0]
    las.intensity = rng.integers(0, 65535, n, dtype=np.uint16)
    las.classification = rng.integers(0, 20, n, dtype=np.uint8)
    las.gps_time = rng.uniform(0, 1e5, n)
    las.red = rng.integers(0, 65535, n, dtype=np.uint16)
    las.return_number = rng.integers(1, 4, n, dtype=np.uint8)
    las.reflectance = rng.standard_normal(n).astype(np.float32)
    las.write(str(path), do_compress=compress)


@pytest.mark.parametrize("fmt", ["las", "laz"])
def test_las_through_the_cli(tmp_path: Path, fmt: str) -> None:
    import laspy

    src, dst, rep = tmp_path / f"in.{fmt}", tmp_path / f"out.{fmt}", tmp_path / "r.json"
    _las(src, terrain_cloud(12000, side=50.0, seed=8), compress=fmt == "laz")
    proc = _cli(str(src), "-o", str(dst), "--tau", "40", "--tile-points", "3000",
                "--report", str(rep))  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    report = json.loads(rep.read_text())
    assert report["streamed"] is True and report["tiles"]["count"] == 4
    a, b = laspy.read(str(src)), laspy.read(str(dst))
    for name in a.point_format.dimension_names:
        if name not in ("X", "Y", "Z"):
            np.testing.assert_array_equal(a[name], b[name], err_msg=name)
    P, _ = read_coordinates(src, fmt)
    expect = smooth(Geometry(P), PARAMS).points
    got = np.c_[b.x, b.y, b.z]
    assert np.max(np.abs(got - expect)) <= 0.0005 + 1e-9  # half the file's scale
    assert b.header.point_count == a.header.point_count
    assert np.allclose(b.header.mins, got.min(axis=0)) and np.allclose(b.header.maxs,
                                                                         got.max(axis=0))


def _ply(path: Path, P: np.ndarray, F: np.ndarray) -> None:
    n, m = P.shape[0], F.shape[0]
    head = (
        "ply\nformat binary_little_endian 1.0\ncomment terrain\n"
        f"element vertex {n}\nproperty float x\nproperty float y\nproperty float z\n"
        "property uchar red\nproperty float quality\n"
        f"element face {m}\nproperty list uchar int vertex_indices\nend_header\n"
    ).encode()
    vdt = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("red", "u1"), ("quality", "<f4")])
    v = np.zeros(n, vdt)
    v["x"], v["y"], v["z"] = P.T
    v["red"] = np.arange(n) % 251
    v["quality"] = np.sqrt(np.arange(n))
    f = np.zeros(m, np.dtype([("n", "u1"), ("v", "<i4", (3,))]))
    f["n"], f["v"] = 3, F
    path.write_bytes(head + v.tobytes() + f.tobytes())


def test_binary_ply_mesh_through_the_cli(tmp_path: Path) -> None:
    P, F = terrain_mesh(110, side=60.0, seed=9)
    src, dst = tmp_path / "in.ply", tmp_path / "out.ply"
    _ply(src, P, F)
    assert streamable(src, "ply")
    proc = _cli(str(src), "-o", str(dst), "--tau", "40", "--tile-points", "3000")
    assert proc.returncode == 0, proc.stderr
    a, b = src.read_bytes(), dst.read_bytes()
    n, body = P.shape[0], a.index(b"end_header\n") + len(b"end_header\n")
    assert a[:body] == b[:body]  # header
    vdt = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("red", "u1"), ("quality", "<f4")])
    va = np.frombuffer(a, vdt, n, body)
    vb = np.frombuffer(b, vdt, n, body)
    np.testing.assert_array_equal(va[["red", "quality"]], vb[["red", "quality"]])
    assert a[body + n * vdt.itemsize :] == b[body + n * vdt.itemsize :]  # faces, byte for byte
    Pin, Fin = read_coordinates(src, "ply")
    assert np.array_equal(Fin, F)
    expect = smooth(Geometry(Pin, faces=Fin), PARAMS).points.astype(np.float32)
    got = np.c_[vb["x"], vb["y"], vb["z"]]
    np.testing.assert_array_equal(got, expect)


def test_xyz_keeps_its_other_columns(tmp_path: Path) -> None:
    P = terrain_cloud(9000, side=40.0, seed=10)
    src, dst = tmp_path / "in.xyz", tmp_path / "out.xyz"
    extra = np.arange(9000) % 97
    lines = ["# x y z intensity"] + [f"{x:.4f} {y:.4f} {z:.4f} {i}"
                                     for (x, y, z), i in zip(P, extra, strict=True)]  # fmt: skip
    src.write_text("\n".join(lines) + "\n")
    Pin, _ = read_coordinates(src, "xyz")
    rewrite(src, dst, "xyz", Pin + 1.0)
    out = dst.read_text().splitlines()
    assert out[0] == "# x y z intensity"
    rows = [line.split() for line in out[1:]]
    assert [int(r[3]) for r in rows] == extra.tolist()
    np.testing.assert_allclose(np.array([r[:3] for r in rows], float), Pin + 1.0, atol=5e-5)
    assert all(len(r[0].split(".")[1]) == 4 for r in rows[:50])  # the input's decimals
