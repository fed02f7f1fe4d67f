"""Seams between adjacent files: ``python -m benchmarks.tiles.seams M N SIGMA`` (issue 43).

An ``M x M`` set of adjacent LAS files (format 3, scale 1 mm, UTM offsets) of ``N`` points
each cut from one terrain (``terrain.heights``, 0.5 m spacing, height noise ``SIGMA``).
Smoothed two ways through the CLI: each file alone (``geosmooth smooth f.las -o out.las``, the
batch's per-file path) and as one batch (``geosmooth smooth dir/*.las -o out/``: one set).
Reported: the RMS height error against the noise-free terrain within 0.5 m of an edge shared
with a neighbouring file, and inside (farther than 5 m from every file edge), CPU seconds of
the CLI processes, the load. One JSON line per run in ``results/seams.jsonl``.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks.tiles import terrain

OUT = Path(__file__).resolve().parent / "results" / "seams.jsonl"
SPACING = 0.5


def make(m: int, n: int, sigma: float, where: Path) -> tuple[float, list[Path]]:
    """The files (row-major) and the side of one file (m)."""
    import laspy

    side = SPACING * np.sqrt(n)
    rng = np.random.default_rng(11)
    paths = []
    for i in range(m):
        for j in range(m):
            xy = rng.uniform(0, side, (n, 2)) + np.array([i * side, j * side])
            z = terrain.heights(xy, m * side, seed=0) + sigma * rng.standard_normal(n)
            header = laspy.LasHeader(point_format=3, version="1.2")
            header.scales = np.array([0.001, 0.001, 0.001])
            header.offsets = np.array([500000.0, 5000000.0, 0.0])
            las = laspy.LasData(header)
            las.x, las.y, las.z = xy[:, 0] + 500000.0, xy[:, 1] + 5000000.0, z
            las.intensity = np.arange(n) % 65535  # an attribute the output must keep
            path = where / f"tile_{i}_{j}.las"
            las.write(str(path))
            paths.append(path)
    return side, paths


def _cli(args: list[str]) -> float:
    """Run ``geosmooth`` nice'd; the CPU seconds of the child."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(["nice", "-n", "5", sys.executable, "-m", "geosmooth", *args, "-q"],
                   check=True, capture_output=True)  # fmt: skip
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def errors(m: int, side: float, paths: list[Path], out: Path) -> dict[str, float]:
    """RMS height error near shared edges and inside; the files' attributes checked."""
    import laspy

    near, inside = [], []
    for path in paths:
        a, b = laspy.read(str(path)), laspy.read(str(out / path.name))
        assert np.array_equal(a.intensity, b.intensity)  # attributes and order kept
        x, y = np.asarray(b.x) - 500000.0, np.asarray(b.y) - 5000000.0
        err = np.asarray(b.z) - terrain.heights(np.c_[x, y], m * side, seed=0)
        i, j = int(path.stem.split("_")[1]), int(path.stem.split("_")[2])
        gaps = []  # distances to the edges shared with a neighbour
        if i > 0:
            gaps.append(x - i * side)
        if i < m - 1:
            gaps.append((i + 1) * side - x)
        if j > 0:
            gaps.append(y - j * side)
        if j < m - 1:
            gaps.append((j + 1) * side - y)
        shared = np.min(gaps, axis=0)
        every = np.min([x - i * side, (i + 1) * side - x, y - j * side, (j + 1) * side - y],
                       axis=0)  # fmt: skip
        near.append(err[shared <= 0.5])
        inside.append(err[every > 5.0])
    e, s = np.concatenate(near), np.concatenate(inside)
    return {"edge": float(np.sqrt(np.mean(e**2))), "inside": float(np.sqrt(np.mean(s**2))),
            "edge_points": int(e.size)}


def main(argv: list[str]) -> None:
    m, n, sigma = int(argv[0]), int(argv[1]), float(argv[2])
    where = Path(f"/tmp/seams-{m}-{n}")
    (where / "in").mkdir(parents=True, exist_ok=True)
    side, paths = make(m, n, sigma, where / "in")
    rows = []
    alone = where / "alone"
    alone.mkdir(exist_ok=True)
    cpu = sum(_cli(["smooth", str(p), "-o", str(alone / p.name)]) for p in paths)
    rows.append({"run": "each file alone", "cpu": cpu, **errors(m, side, paths, alone)})
    together = where / "set"
    cpu = _cli(["smooth", *map(str, paths), "-o", str(together) + "/"])
    rows.append({"run": "one set (batch)", "cpu": cpu, **errors(m, side, paths, together)})
    for row in rows:
        row.update(m=m, n=n, sigma=sigma, ratio=row["edge"] / row["inside"],
                   load=os.getloadavg()[0], when=time.strftime("%Y-%m-%d %H:%M:%S"))
        print(json.dumps(row), flush=True)
        with open(OUT, "a") as fh:
            fh.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main(sys.argv[1:])
