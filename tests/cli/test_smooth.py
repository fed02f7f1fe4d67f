"""End-to-end runs of ``geosmooth smooth`` on the shared real data (subprocess, real files)."""

from __future__ import annotations

import json
import os
import pty
import subprocess
import sys
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from service.io import read_geometry

Run = Callable[..., subprocess.CompletedProcess[str]]


def _points(path: Path, **kw: object) -> np.ndarray:
    return read_geometry(path, **kw).geometry.points  # type: ignore[arg-type]


def _progress_lines(stderr: str) -> list[str]:
    return [ln for ln in stderr.splitlines() if ln.startswith("geosmooth: iteration")]


def test_bunny_tau_report_and_progress(cli: Run, data: Callable[[str], Path], tmp_path: Path):
    src = data("bunny.ply")
    out, rep = tmp_path / "bunny-smooth.ply", tmp_path / "report.json"
    tau = 2e-4
    # free displacement, binary float32 output (the ASCII input's encoding would keep its 6
    # digits): the deviations recomputed from the file below match to 1e-6
    args = ["--tau", tau, "--report", rep, "--displacement", "free", "--no-ascii"]
    res = cli(["smooth", src, "-o", out, *args])
    assert res.returncode == 0, res.stderr
    assert res.stdout == ""

    before, after = read_geometry(src), read_geometry(out)
    assert after.geometry.n == before.geometry.n == 8171
    np.testing.assert_array_equal(after.geometry.faces, before.geometry.faces)
    assert not np.array_equal(after.geometry.points, before.geometry.points)

    report = json.loads(rep.read_text())
    for key in (
        "lambda", "phi", "tau", "relative_error", "converged", "iterations", "factorizations",
        "history", "n_points", "dimension", "laplacian", "weights", "rms_displacement",
        "max_displacement", "timings", "solver", "input", "output", "params",
    ):  # fmt: skip
        assert key in report, key
    assert report["tau"] == pytest.approx(tau)
    assert report["converged"] is True
    assert report["n_points"] == 8171 and report["dimension"] == 3
    assert report["params"]["tau"] == tau and report["params"]["laplacian"] == "normalized"
    assert report["input"] == str(src) and report["output"] == str(out)
    assert len(report["history"]) == report["iterations"] >= 1
    assert {"lambda", "phi"} <= set(report["history"][-1])
    tol = report["params"]["tolerance"]
    assert abs(report["phi"] - tau) / tau <= tol
    # phi recomputed from the two files: sum of squared displacements (all weights 1).
    d2 = ((after.geometry.points - before.geometry.points) ** 2).sum(axis=1)
    assert report["phi"] == pytest.approx(d2.sum(), rel=1e-6)
    # one point's move from float32 coordinates: within a few units of their last place
    ulp = float(np.finfo(np.float32).eps * np.abs(after.geometry.points).max())
    assert report["max_displacement"] == pytest.approx(np.sqrt(d2.max()), abs=4 * ulp)
    assert report["rms_displacement"] == pytest.approx(np.sqrt(d2.mean()), rel=1e-6)

    # stderr is not a terminal here: one plain line per lambda iteration, then the summary.
    lines = _progress_lines(res.stderr)
    assert len(lines) == report["iterations"]
    assert "\r" not in res.stderr
    assert "tau=" in lines[-1] and "rel.error=" in lines[-1]
    assert "converged" in res.stderr and f"{report['lambda']:.4e}" in res.stderr


def test_bunny_fixed_file_fix_boundary_quiet(cli: Run, data: Callable[[str], Path], tmp_path: Path):
    src = data("bunny.ply")
    fixed = [0, 17, 4000, 8170]
    fixed_file = tmp_path / "fixed.txt"
    fixed_file.write_text("# points to pin\n0, 17\n4000  # middle\n\n8170\n")
    out, rep = tmp_path / "pinned.ply", tmp_path / "report.json"
    res = cli([
        "smooth", src, "-o", out, "--tau", "2e-4", "--fixed", fixed_file, "--fix-boundary",
        "--quiet", "--report", rep,
    ])  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert res.stdout == "" and res.stderr == ""

    before, after = read_geometry(src), read_geometry(out)
    p, x = before.geometry.points, after.geometry.points
    assert np.array_equal(x[fixed], p[fixed])  # bit-identical
    # Boundary vertices: on an edge used by exactly one triangle (duplicates counted).
    faces = before.geometry.faces
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    counts = Counter(map(tuple, edges.tolist()))
    boundary = sorted({v for e, c in counts.items() if c == 1 for v in e})
    assert len(boundary) > 100
    assert np.array_equal(x[boundary], p[boundary])
    moved = np.setdiff1d(np.arange(len(p)), np.union1d(boundary, fixed))
    assert np.abs(x[moved] - p[moved]).max() > 0
    report = json.loads(rep.read_text())
    assert report["n_fixed"] >= len(set(fixed) | set(boundary))
    assert abs(report["phi"] - 2e-4) / 2e-4 <= report["params"]["tolerance"]


def test_gps_polylines_rms_fix_boundary(cli: Run, data: Callable[[str], Path], tmp_path: Path):
    src = data("korita-zbevnica.obj")
    out, rep = tmp_path / "track.obj", tmp_path / "report.json"
    rms = 3.0
    # --precision float64: the file then holds the engine's points exactly (by default a text
    # output keeps the input's digits, here 1 mm, issue 11), so phi can be recomputed from it
    args = ["smooth", src, "-o", out, "--rms", rms, "--fix-boundary", "--report", rep]
    res = cli([*args, "--precision", "float64"])
    assert res.returncode == 0, res.stderr

    before, after = read_geometry(src), read_geometry(out)
    assert after.geometry.n == before.geometry.n == 871
    assert len(after.polylines) == len(before.polylines) == 3
    for a, b in zip(after.polylines, before.polylines, strict=True):
        np.testing.assert_array_equal(a.indices, b.indices)
        assert a.closed == b.closed is False
    ends = [int(i) for pl in before.polylines for i in (pl.indices[0], pl.indices[-1])]
    assert np.array_equal(after.geometry.points[ends], before.geometry.points[ends])

    report = json.loads(rep.read_text())
    assert report["n_fixed"] == 6
    assert report["params"]["rms"] == rms and report["params"]["tau"] is None
    # --rms: tau = rms^2 * sum of w_i^2 over the points that can move (here 871 - 6 endpoints).
    assert report["tau"] == pytest.approx((871 - 6) * rms**2, rel=1e-12)
    assert "tau=7.7850e+03" in res.stderr  # the progress line shows the engine's own tau
    assert abs(report["phi"] - report["tau"]) / report["tau"] <= report["params"]["tolerance"]
    d2 = ((after.geometry.points - before.geometry.points) ** 2).sum()
    assert report["phi"] == pytest.approx(d2, rel=1e-6)
    assert report["kind"] == "curve"


def test_featuretype_weld(cli: Run, data: Callable[[str], Path], tmp_path: Path):
    src = data("featuretype.ply")
    out, rep = tmp_path / "feature.ply", tmp_path / "report.json"
    # --precision float64: exact points in the file (by default float32 in, float32 out)
    args = ["smooth", src, "-o", out, "--tau", "1e-3", "--weld", "--report", rep]
    res = cli([*args, "--precision", "float64"])
    assert res.returncode == 0, res.stderr
    assert "welded from 5096 vertices" in res.stderr

    before, after = read_geometry(src, weld=False), read_geometry(out, weld=False)  # as stored
    assert after.geometry.n == before.geometry.n == 5096  # the file's vertices, not the welded
    np.testing.assert_array_equal(after.geometry.faces, before.geometry.faces)
    p, x = before.geometry.points, after.geometry.points
    uniq, first, inverse = np.unique(p, axis=0, return_index=True, return_inverse=True)
    assert len(uniq) == 1722
    # Vertices that coincided in the input still coincide: they were smoothed as one.
    np.testing.assert_array_equal(x, x[first][inverse.reshape(-1)])
    report = json.loads(rep.read_text())
    assert report["n_points"] == 1722
    phi_welded = ((x[first] - p[first]) ** 2).sum()
    assert report["phi"] == pytest.approx(phi_welded, rel=1e-6)
    assert abs(report["phi"] - 1e-3) / 1e-3 <= report["params"]["tolerance"]


def test_point_cloud_xyz_on_a_terminal(data: Callable[[str], Path], tmp_path: Path):
    """A point cloud, with stderr on a pseudo-terminal: one line updated with carriage returns."""
    src = data("points_agisoft.xyz")
    out = tmp_path / "cloud.xyz"
    master, slave = pty.openpty()
    try:
        args = ["smooth", str(src), "-o", str(out), "--rms", "0.05", "--search", "rational"]
        proc = subprocess.Popen(
            [sys.executable, "-m", "service.cli", *args],
            stdout=subprocess.DEVNULL,
            stderr=slave,
        )
        os.close(slave)
        chunks = []
        while True:  # read while it runs, so a full pty buffer can never block the child
            try:
                chunk = os.read(master, 65536)
            except OSError:  # EIO: the child exited and the terminal is drained
                break
            if not chunk:
                break
            chunks.append(chunk)
        returncode = proc.wait(timeout=120)
    finally:
        os.close(master)
    tty_text = b"".join(chunks).decode()
    assert returncode == 0, tty_text
    # Every iteration overwrites the same line ("\r"); none starts a new one ("\n").
    assert tty_text.count("\rgeosmooth: iteration") >= 2
    assert "\ngeosmooth: iteration" not in tty_text
    assert "converged" in tty_text

    before, after = read_geometry(src), read_geometry(out)
    assert after.geometry.n == before.geometry.n == 100
    assert after.geometry.kind == "cloud"
    d2 = ((after.geometry.points - before.geometry.points) ** 2).sum()
    assert d2 == pytest.approx(100 * 0.05**2, rel=2e-3)


def test_console_script_version() -> None:
    """The installed ``geosmooth`` entry point runs (``pip install -e .`` made it)."""
    script = Path(sys.executable).parent / "geosmooth"
    if not script.exists():
        pytest.skip("console script not installed next to this interpreter")
    res = subprocess.run(
        [str(script), "--version"], capture_output=True, text=True, timeout=60, check=False
    )
    assert res.returncode == 0
    assert res.stdout.startswith("geosmooth ")
