"""Read/write time and peak memory per format and size, against trimesh, laspy and Open3D.

Every measurement runs in a fresh subprocess (``python bench_io.py --one TOOL FMT PATH``):
peak memory is the growth of the peak resident set (``VmHWM``) over the process's level after
its imports, so C++ allocations (Open3D, lazrs) count like numpy's. Times are wall-clock
medians of ``--repeat`` runs; compare the ratios within one run (the machine is shared).

Usage::

    nice -n 10 python benchmarks/io/bench_io.py            # 1M points / vertices
    nice -n 10 python benchmarks/io/bench_io.py --full     # also 20M points (LAS, LAZ, PLY)

Writes a markdown table to stdout (results of a run are kept in ``results.md``).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
CACHE = Path(tempfile.gettempdir()) / "geosmooth-bench-io"


def _grid_mesh(n_side: int) -> tuple[np.ndarray, np.ndarray]:
    u, v = np.meshgrid(np.linspace(0, 1, n_side), np.linspace(0, 1, n_side))
    pts = np.column_stack([u.ravel(), v.ravel(), 0.05 * np.sin(6 * u.ravel()) * v.ravel()])
    i = np.arange(n_side - 1)
    a = (i[:, None] * n_side + i[None, :]).ravel()
    faces = np.concatenate(
        [
            np.column_stack([a, a + 1, a + n_side]),
            np.column_stack([a + 1, a + n_side + 1, a + n_side]),
        ]
    )
    return pts.astype(np.float32), faces.astype(np.int32)


def make(fmt: str, n: int) -> Path:
    """A benchmark input (cached)."""
    CACHE.mkdir(exist_ok=True)
    path = CACHE / f"bench_{n}.{fmt}"
    if path.exists():
        return path
    rng = np.random.default_rng(0)
    if fmt in ("las", "laz"):
        import laspy

        header = laspy.LasHeader(point_format=3, version="1.2")
        header.scales = np.array([0.001, 0.001, 0.001])
        header.offsets = np.array([650000.0, 5600000.0, 0.0])
        with laspy.open(path, mode="w", header=header, do_compress=fmt == "laz") as w:
            for s in range(0, n, 2_000_000):
                k = min(2_000_000, n - s)
                rec = laspy.ScaleAwarePointRecord.zeros(k, header=header)
                rec.x = 650000 + rng.uniform(0, 500, k)
                rec.y = 5600000 + rng.uniform(0, 500, k)
                rec.z = rng.uniform(0, 50, k)
                rec.intensity = rng.integers(0, 60000, k)
                rec.classification = rng.integers(0, 10, k)
                rec.gps_time = rng.uniform(0, 1e5, k)
                rec.red, rec.green, rec.blue = rng.integers(0, 60000, (3, k))
                w.write_points(rec)
        return path
    import trimesh

    side = int(np.sqrt(n))
    pts, faces = _grid_mesh(side)
    mesh = trimesh.Trimesh(pts, faces, process=False)
    if fmt == "ply-cloud":
        path = CACHE / f"bench_{n}_cloud.ply"
        cloud = rng.normal(size=(n, 3)).astype(np.float32)
        colours = rng.integers(0, 255, (n, 3), dtype=np.uint8)
        dt = np.dtype(
            [
                ("x", "<f4"),
                ("y", "<f4"),
                ("z", "<f4"),
                ("red", "u1"),
                ("green", "u1"),
                ("blue", "u1"),
            ]
        )
        rec = np.empty(n, dtype=dt)
        for j, c in enumerate("xyz"):
            rec[c] = cloud[:, j]
        for j, c in enumerate(("red", "green", "blue")):
            rec[c] = colours[:, j]
        head = (
            f"ply\nformat binary_little_endian 1.0\nelement vertex {n}\nproperty float x\n"
            "property float y\nproperty float z\nproperty uchar red\nproperty uchar green\n"
            "property uchar blue\nend_header\n"
        ).encode()
        with open(path, "wb") as fh:
            fh.write(head)
            fh.write(rec.tobytes())
        return path
    if fmt == "xyz":
        np.savetxt(path, rng.normal(size=(n, 3)), fmt="%.6f")
        return path
    if fmt == "pcd":
        sys.path.insert(0, str(ROOT))
        from service.core.geometry import Geometry
        from service.io import GeometryDocument, save_geometry

        save_geometry(
            GeometryDocument.from_geometry(Geometry(rng.normal(size=(n, 3)))),
            path,
            precision="float32",
        )
        return path
    data = mesh.export(file_type=fmt)
    path.write_bytes(data if isinstance(data, bytes) else data.encode())
    return path


def _peers(fmt: str) -> list[str]:
    table = {
        "ply": ["geosmooth", "trimesh", "open3d-mesh"],
        "ply-cloud": ["geosmooth", "trimesh", "open3d-cloud"],
        "obj": ["geosmooth", "trimesh", "open3d-mesh"],
        "stl": ["geosmooth", "trimesh", "open3d-mesh"],
        "xyz": ["geosmooth", "open3d-cloud"],
        "pcd": ["geosmooth", "open3d-cloud"],
        "las": ["geosmooth", "laspy"],
        "laz": ["geosmooth", "laspy"],
    }
    return table[fmt]


def _hwm() -> int:
    """Peak resident set of this process (VmHWM: reset by exec, unlike ru_maxrss)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) * 1024
    raise RuntimeError("no VmHWM in /proc/self/status")


def one(tool: str, fmt: str, path: str) -> dict[str, float]:
    """Read (and for geosmooth write) one file in this process; print JSON numbers."""
    sys.path.insert(0, str(ROOT))
    if tool == "geosmooth":
        import importlib

        from service.io import read_geometry, save_geometry

        for mod in ("plain", "ply", "ply_write", "obj", "obj_write", "xyz", "stl", "pcd", "las"):
            importlib.import_module(f"service.io.{mod}")  # lazy imports out of the timing
        importlib.import_module("service.core.geometry")
    elif tool == "trimesh":
        import trimesh
    elif tool.startswith("open3d"):
        import open3d as o3d
    else:
        import laspy
    base = _hwm()
    t0 = time.perf_counter()
    out: dict[str, float] = {}
    if tool == "geosmooth":
        doc = read_geometry(path)
        out["read_s"] = time.perf_counter() - t0
        out["read_peak"] = _hwm() - base
        moved = doc.geometry.points * 1.0001
        dest = Path(path).with_name("out_" + Path(path).name)
        t1 = time.perf_counter()
        save_geometry(doc, dest, points=moved)
        out["write_s"] = time.perf_counter() - t1
        dest.unlink()
    elif tool == "trimesh":
        trimesh.load(path, process=False, file_type=Path(path).suffix[1:])
    elif tool == "open3d-mesh":
        o3d.io.read_triangle_mesh(path)
    elif tool == "open3d-cloud":
        o3d.io.read_point_cloud(path)
    else:
        laspy.read(path)
    out.setdefault("read_s", time.perf_counter() - t0)
    out["peak"] = _hwm() - base
    return out


def measure(tool: str, fmt: str, path: Path, repeat: int) -> dict[str, float]:
    runs = []
    for _ in range(repeat):
        res = subprocess.run(
            [sys.executable, __file__, "--one", tool, fmt, str(path)],
            capture_output=True,
            text=True,
            check=True,
            env={**os.environ, "PYTHONPATH": str(ROOT)},
        )
        runs.append(json.loads(res.stdout.strip().splitlines()[-1]))
    return {k: statistics.median(r[k] for r in runs) for k in runs[0]}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--one", nargs=3)
    ap.add_argument("--full", action="store_true")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    if args.one:
        print(json.dumps(one(*args.one)))
        return
    sizes = [1_000_000] + ([20_000_000] if args.full else [])
    print(f"load: {os.getloadavg()}")
    print(
        "| format | n | size MB | tool | read s | read peak / size | write s |"
        " read+write peak / size |"
    )
    print("|---|---:|---:|---|---:|---:|---:|---:|")
    for n in sizes:
        fmts = (
            ["ply", "ply-cloud", "obj", "stl", "xyz", "pcd", "las", "laz"]
            if n < 2e7
            else ["las", "laz", "ply-cloud"]
        )
        for fmt in fmts:
            path = make(fmt, n)
            size = path.stat().st_size
            for tool in _peers(fmt):
                r = measure(tool, fmt, path, 1 if n >= 2e7 else args.repeat)
                read_peak = r.get("read_peak", r["peak"]) / size
                write = f"{r['write_s']:.2f} | {r['peak'] / size:.2f}" if "write_s" in r else " |"
                print(
                    f"| {fmt} | {n} | {size / 1e6:.1f} | {tool} | {r['read_s']:.2f} |"
                    f" {read_peak:.2f} | {write} |",
                    flush=True,
                )


if __name__ == "__main__":
    main()
