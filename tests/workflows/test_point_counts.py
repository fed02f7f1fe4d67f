"""The report counts what the file holds (issue 38): points in, points solved after welding,
points out and the vertices welded, each named; the counts checked against the files' own
headers and an independent weld (numpy's unique rows)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import trimesh

import geosmooth
from tests.shared_data import shared_data_dir

FEATURETYPE = shared_data_dir() / "featuretype.ply"


def _ply_vertices(path: Path) -> int:
    head = path.read_bytes()[:4096].split(b"end_header")[0].decode("ascii", "replace")
    found = re.search(r"element vertex (\d+)", head)
    assert found is not None
    return int(found.group(1))


@pytest.mark.skipif(not FEATURETYPE.is_file(), reason="shared data not available")
def test_a_welded_ply_reports_the_files_vertices_and_the_points_solved(tmp_path: Path) -> None:
    raw = trimesh.load(FEATURETYPE, process=False)
    n_file = _ply_vertices(FEATURETYPE)
    distinct = np.unique(np.asarray(raw.vertices), axis=0).shape[0]
    assert n_file == len(raw.vertices) == 5096 and distinct == 1722
    out = tmp_path / "out.ply"
    result = geosmooth.smooth_file(FEATURETYPE, out, {"rms": 0.01})
    report = result.report()
    assert report["points_in"] == n_file
    assert report["points_solved"] == report["n_points"] == distinct
    assert report["welded_pairs"] == n_file - distinct
    assert report["points_out"] == _ply_vertices(out) == n_file


def test_an_array_reports_its_own_points_in_solved_and_out() -> None:
    P = np.random.default_rng(0).standard_normal((200, 3))
    _, result = geosmooth.smooth(P, {"rms": 0.01}, full_output=True)
    counts = {k: result.report()[k] for k in ("points_in", "points_solved", "points_out")}
    assert counts == dict.fromkeys(counts, 200) and result.report()["welded_pairs"] == 0


def test_dropped_outliers_leave_the_output(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    u, v = rng.uniform(-1, 1, (2, 1500))
    P = np.column_stack([u, v, 0.01 * rng.standard_normal(1500)])
    P[:6, 2] += 1.0  # six strays far off the sheet
    src, out = tmp_path / "in.xyz", tmp_path / "out.xyz"
    np.savetxt(src, P)
    report = geosmooth.smooth_file(src, out, {"outliers": "drop"}).report()
    written = np.loadtxt(out).shape[0]
    assert report["outlier_count"] >= 6 and report["points_in"] == 1500
    assert report["points_out"] == written == 1500 - report["outlier_count"]
