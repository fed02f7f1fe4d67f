"""Outliers in the written file (issue 31): LAS class 7 read back with laspy, a PLY/PCD
``outlier`` attribute, and ``drop`` removing rows with the attributes kept aligned."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from service.core.geometry import Geometry
from service.core.params import SmoothingParams
from service.io import read_geometry
from service.io.document import GeometryDocument
from service.workflows.smooth_file import smooth_file


def _cloud() -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(4)
    U = rng.normal(size=(2000, 3))
    U /= np.linalg.norm(U, axis=1, keepdims=True)
    P = 10.0 * U * (1 + 0.01 * rng.normal(size=(2000, 1)))
    strays = np.array([5, 300, 1200, 1999])
    P[strays] = 10.0 * U[strays] * 1.5
    return np.round(P, 4), strays


def _doc(P: np.ndarray) -> GeometryDocument:
    ids = np.arange(len(P), dtype=np.int32)
    return GeometryDocument.from_geometry(Geometry(P), "xyz").with_extras(
        attributes={"intensity": ids.astype(np.uint16), "ident": ids})


def test_las_input_gets_class_7_on_its_outliers_and_keeps_the_other_classes(
    tmp_path: Path,
) -> None:
    laspy = pytest.importorskip("laspy")
    P, strays = _cloud()
    header = laspy.LasHeader(point_format=1, version="1.2")
    header.scales = np.array([1e-4] * 3)
    header.offsets = np.floor(P.min(axis=0))
    las = laspy.LasData(header)
    las.x, las.y, las.z = P[:, 0], P[:, 1], P[:, 2]
    las.classification = np.full(len(P), 2, np.uint8)
    src = tmp_path / "in.las"
    las.write(src)
    done = smooth_file(src, tmp_path / "out.las", SmoothingParams())
    out = laspy.read(tmp_path / "out.las")
    flagged = np.flatnonzero(np.asarray(out.classification) == 7)
    assert set(strays.tolist()) <= set(flagged.tolist())
    assert flagged.tolist() == done.result.outliers.tolist()
    assert np.all(np.delete(np.asarray(out.classification), flagged) == 2)
    assert np.array_equal(out.X[flagged], las.X[flagged])  # the stored integers, unchanged


@pytest.mark.parametrize("fmt", ["ply", "pcd", "las"])
def test_a_flag_in_every_format_that_holds_one(tmp_path: Path, fmt: str) -> None:
    P, strays = _cloud()
    target = tmp_path / f"out.{fmt}"
    done = smooth_file(_doc(P), target, SmoothingParams(), out_fmt=fmt)
    idx = done.result.outliers
    assert done.result.outlier_mode == "flag" and set(strays.tolist()) <= set(idx.tolist())
    back = read_geometry(target)
    if fmt == "las":
        import laspy

        flags = np.asarray(laspy.read(target).classification) == 7
    else:
        flags = np.asarray(back.attributes["outlier"]) == 1
    assert np.flatnonzero(flags).tolist() == idx.tolist()
    assert np.allclose(back.geometry.points[idx], P[idx], atol=1e-4)


@pytest.mark.parametrize("fmt", ["xyz", "ply"])
def test_drop_removes_the_rows_and_keeps_attributes_aligned(tmp_path: Path, fmt: str) -> None:
    P, strays = _cloud()
    target = tmp_path / f"out.{fmt}"
    done = smooth_file(_doc(P), target, SmoothingParams(outliers="drop"), out_fmt=fmt)
    idx = done.result.outliers
    back = read_geometry(target)
    keep = np.setdiff1d(np.arange(len(P)), idx)
    assert back.geometry.n == len(P) - idx.size and set(strays.tolist()) <= set(idx.tolist())
    ident = np.asarray(list(back.attributes.values())[-1]).astype(np.int64)  # XYZ: unnamed
    assert ident.tolist() == keep.tolist()
    assert np.allclose(back.geometry.points, done.result.points[keep], atol=1e-3)
