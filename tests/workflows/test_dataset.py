"""Adjacent files smoothed as one surface (service.workflows.dataset, issue 43): the sets a
batch forms, and a 2 x 2 set of LAS files through the real CLI against the tiled engine run on
the files' points put together (read back with laspy)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from service.core import Geometry, SmoothingParams
from service.core.tiles import smooth_tiled
from service.workflows.dataset import adjacent_sets, file_box
from tests.cli.conftest import run_cli
from tests.core.tiles.terrain import heights

SIDE = 30.0  # metres per file; 0.5 m spacing


def _files(where: Path, m: int = 2, n: int = 3600, gap: float = 0.0) -> list[Path]:
    import laspy

    rng = np.random.default_rng(4)
    out = []
    for i in range(m):
        for j in range(m):
            xy = rng.uniform(0, SIDE, (n, 2)) + np.array([i, j]) * (SIDE + gap)
            z = heights(xy, 500.0, seed=1) + 0.1 * rng.standard_normal(n)  # smooth at 0.5 m
            header = laspy.LasHeader(point_format=3, version="1.2")
            header.scales = np.array([0.001, 0.001, 0.001])
            header.offsets = np.array([400000.0, 6000000.0, 0.0])
            las = laspy.LasData(header)
            las.x, las.y, las.z = xy[:, 0] + 400000.0, xy[:, 1] + 6000000.0, z
            las.intensity = rng.integers(0, 65535, n, dtype=np.uint16)
            las.gps_time = rng.uniform(0, 1e5, n)
            path = where / f"t{i}{j}.las"
            las.write(str(path))
            out.append(path)
    return out


def test_adjacent_sets_group_touching_boxes_transitively() -> None:
    box = lambda x0, y0: (np.array([x0, y0, 0.0]), np.array([x0 + 10, y0 + 10, 1.0]), 0.5)  # noqa: E731
    boxes = [box(0, 0), box(10.5, 0), box(21, 0), box(50, 50), box(0, 11)]
    groups = sorted(sorted(g) for g in adjacent_sets(boxes))
    # 1.5 spacings between 0-1 and 1-2 (within 3), 0-4 1 spacing; 3 far from all
    assert groups == [[0, 1, 2, 4], [3]]


def test_file_box_reads_the_las_header(tmp_path: Path) -> None:
    import laspy

    path = _files(tmp_path, m=1, n=900)[0]
    lo, hi, spacing = file_box(path, "las")
    las = laspy.read(str(path))
    assert lo[0] == pytest.approx(float(np.min(las.x)), abs=1e-3)
    assert hi[1] == pytest.approx(float(np.max(las.y)), abs=1e-3)
    assert spacing == pytest.approx(1.0, rel=0.05)  # 900 points on 30 x 30 m


def test_a_batch_of_adjacent_las_files_is_one_surface(tmp_path: Path) -> None:
    import laspy

    src = tmp_path / "in"
    src.mkdir()
    paths = _files(src)
    out = tmp_path / "out"
    res = run_cli(["smooth", *paths, "-o", f"{out}/"], timeout=600)
    assert res.returncode == 0, res.stderr
    assert res.stderr.count("one set of 4 adjacent files") == 4, res.stderr
    # the engine's tiled run on the four files put together, each file one core
    parts = [laspy.read(str(p)) for p in paths]
    P = np.concatenate([np.c_[a.x, a.y, a.z] for a in parts])
    sizes = np.cumsum([0] + [len(a.x) for a in parts])
    cores = [np.arange(sizes[i], sizes[i + 1]) for i in range(len(parts))]
    want = smooth_tiled(Geometry(P), SmoothingParams(), max(np.diff(sizes)), cores=cores)
    for i, (path, a) in enumerate(zip(paths, parts, strict=True)):
        b = laspy.read(str(out / path.name))
        assert b.header.offsets.tolist() == a.header.offsets.tolist()  # its own header
        assert np.array_equal(b.intensity, a.intensity)  # attributes in the same order
        assert np.array_equal(b.gps_time, a.gps_time)
        got = np.c_[b.x, b.y, b.z]
        assert np.abs(got - want.result.points[sizes[i]:sizes[i + 1]]).max() <= 1e-3
        assert np.abs(got - np.c_[a.x, a.y, a.z]).max() > 0.01  # smoothed


def test_files_apart_are_smoothed_each_alone(tmp_path: Path) -> None:
    src = tmp_path / "in"
    src.mkdir()
    paths = _files(src, gap=20.0)
    res = run_cli(["smooth", *paths, "-o", f"{tmp_path / 'out'}/"], timeout=600)
    assert res.returncode == 0, res.stderr
    assert "adjacent files" not in res.stderr
