"""Defaults that follow the input: STL is welded, a PLY keeps its encoding (issue 11).

Checked on the output itself: copies of one input vertex stay together (one smoothed point)
when welded, and come apart when each triangle is smoothed on its own (``--no-weld``).
"""

from __future__ import annotations

import subprocess
from collections.abc import Callable
from pathlib import Path

import numpy as np
import trimesh

Run = Callable[..., subprocess.CompletedProcess[str]]


def _noisy_sphere_stl(path: Path) -> np.ndarray:
    mesh = trimesh.creation.icosphere(subdivisions=2)
    rng = np.random.default_rng(7)
    mesh.vertices = mesh.vertices + 0.02 * rng.standard_normal(mesh.vertices.shape)
    path.write_bytes(mesh.export(file_type="stl"))
    return np.asarray(mesh.vertices[mesh.faces].reshape(-1, 3))  # the file's corner order


def _corner_spread(path: Path, corners: np.ndarray) -> float:
    """Largest distance between output copies of one input vertex."""
    out = trimesh.load(path, file_type="stl", process=False)
    X = np.asarray(out.vertices[out.faces].reshape(-1, 3))
    _, group = np.unique(corners, axis=0, return_inverse=True)
    spread = 0.0
    for g in range(group.max() + 1):
        copies = X[group.ravel() == g]
        spread = max(spread, float(np.ptp(copies, axis=0).max()))
    return spread


def test_stl_is_welded_by_default_and_not_with_no_weld(cli: Run, tmp_path: Path) -> None:
    src = tmp_path / "sphere.stl"
    corners = _noisy_sphere_stl(src)
    welded, split = tmp_path / "welded.stl", tmp_path / "split.stl"
    res = cli(["smooth", src, "-o", welded, "--lam", "1"])
    assert res.returncode == 0, res.stderr
    assert "welded from" in res.stderr
    assert _corner_spread(welded, corners) == 0.0
    out = trimesh.load(welded, file_type="stl", process=False)
    assert np.abs(out.vertices[out.faces].reshape(-1, 3) - corners).max() > 1e-3  # smoothed
    res = cli(["smooth", src, "-o", split, "--lam", "1", "--no-weld"])
    assert res.returncode == 0, res.stderr
    assert _corner_spread(split, corners) > 1e-3  # every triangle on its own


def test_ply_output_keeps_the_input_encoding_unless_told(cli: Run, tmp_path: Path) -> None:
    mesh = trimesh.creation.icosphere(subdivisions=1)
    src = tmp_path / "in.ply"
    src.write_bytes(mesh.export(file_type="ply", encoding="ascii"))
    for flag, expected in (([], b"format ascii"), (["--no-ascii"], b"format binary_little")):
        out = tmp_path / f"out{len(flag)}.ply"
        res = cli(["smooth", src, "-o", out, "--lam", "1", "-q", *flag])
        assert res.returncode == 0, res.stderr
        assert expected in out.read_bytes()[:200]
        assert len(trimesh.load(out, process=False).vertices) == len(mesh.vertices)
