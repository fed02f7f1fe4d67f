"""Each error class: one line on stderr, no traceback, the exit status documented in --help."""

from __future__ import annotations

import re
import subprocess
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from service.cli import EXIT_CODES
from service.io import read_geometry

Run = Callable[..., subprocess.CompletedProcess[str]]


def _one_error_line(res: subprocess.CompletedProcess[str], code: int) -> str:
    assert res.returncode == code, (res.returncode, res.stderr)
    assert code in EXIT_CODES
    lines = res.stderr.splitlines()
    assert len(lines) == 1, res.stderr
    assert lines[0].startswith("geosmooth: error: ")
    assert "Traceback" not in res.stderr
    assert res.stdout == ""
    return lines[0]


def test_missing_input_file(cli: Run, tmp_path: Path):
    res = cli(["smooth", tmp_path / "nope.ply", "-o", tmp_path / "o.ply", "--tau", "1"])
    line = _one_error_line(res, 3)
    assert "nope.ply" in line and "No such file" in line
    assert not (tmp_path / "o.ply").exists()


def test_unknown_format_is_refused(cli: Run, tmp_path: Path):
    svg = tmp_path / "shape.svg"  # GPX, once refused here, is read since issue 11
    svg.write_text("<svg></svg>")
    res = cli(["smooth", svg, "-o", tmp_path / "o.obj", "--tau", "1"])
    assert "svg" in _one_error_line(res, 3).lower()


def test_malformed_file(cli: Run, tmp_path: Path):
    bad = tmp_path / "bad.ply"
    bad.write_text(
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nend_header\n0 0 0\n1 oops 0\n"
    )
    res = cli(["smooth", bad, "-o", tmp_path / "o.ply", "--tau", "1"])
    assert "bad.ply" in _one_error_line(res, 3)


def test_tau_too_large_gives_the_valid_range(cli: Run, data: Callable[[str], Path], tmp_path: Path):
    src = data("korita-zbevnica.obj")
    doc = read_geometry(src)
    p = doc.geometry.points
    # The report's ends (--ends pulled), unit weights, nothing fixed: phi(0) is the squared
    # deviation from the centroid (eq. 14), taken per connected part (the 3 separate polylines).
    res = cli(["smooth", src, "-o", tmp_path / "o.obj", "--tau", "1e15", "--ends", "pulled"])
    line = _one_error_line(res, 4)
    match = re.search(r"valid range is \(0, ([0-9.e+-]+)\)", line)
    assert match, line
    phi0 = sum(((p[pl.indices] - p[pl.indices].mean(axis=0)) ** 2).sum() for pl in doc.polylines)
    assert float(match.group(1)) == pytest.approx(phi0, rel=1e-5)
    # The default pins the open polylines' ends (issue 21): the smoothness rows are those of the
    # free points, and the lambda -> 0 limit makes them zero: with uniform weights each polyline
    # becomes the straight segment between its ends, at evenly spaced parameters (closed form).
    # The engine takes the limit at its lambda floor (1e-13 ||M||): within 1e-3 here, below it.
    res = cli(["smooth", src, "-o", tmp_path / "o.obj", "--tau", "1e15"])
    match = re.search(r"valid range is \(0, ([0-9.e+-]+)\)", _one_error_line(res, 4))
    assert match
    phi0 = 0.0
    for pl in doc.polylines:
        q = p[pl.indices]
        t = np.linspace(0.0, 1.0, len(q))[:, None]
        phi0 += float(((q - (q[0] + t * (q[-1] - q[0]))) ** 2).sum())
    assert phi0 * (1 - 1e-3) <= float(match.group(1)) <= phi0


def test_fixed_index_out_of_range(cli: Run, data: Callable[[str], Path], tmp_path: Path):
    fixed = tmp_path / "fixed.txt"
    fixed.write_text("1 2 99999\n")
    res = cli([
        "smooth", data("korita-zbevnica.obj"), "-o", tmp_path / "o.obj", "--tau", "100",
        "--fixed", fixed,
    ])  # fmt: skip
    line = _one_error_line(res, 4)
    assert "--fixed" in line and "99999" in line


def test_unwritable_output(cli: Run, data: Callable[[str], Path], tmp_path: Path):
    out = tmp_path / "no-such-dir" / "o.obj"
    res = cli(["smooth", data("korita-zbevnica.obj"), "-o", out, "--rms", "3", "--quiet"])
    line = _one_error_line(res, 6)
    assert "o.obj" in line


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["--tau", "1", "--lam", "0.1"], "not allowed with argument"),
        (["--tau", "-1"], "--tau: must be greater than 0"),
    ],
)
def test_usage_errors(cli: Run, tmp_path: Path, args: list[str], expected: str):
    # The input does not even exist: parameters are checked before any file is touched.
    res = cli(["smooth", tmp_path / "in.ply", "-o", tmp_path / "o.ply", *args])
    assert expected in _one_error_line(res, 2)
