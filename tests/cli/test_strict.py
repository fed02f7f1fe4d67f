"""``--strict``: a shape warning fails the run with its own exit status and nothing is written;
the default on noise-free data says "no noise found" in the summary (issue 20)."""

from __future__ import annotations

import json
import subprocess
from collections.abc import Callable
from pathlib import Path

import numpy as np

from service.exit_codes import EXIT_OK, EXIT_SHAPE

Run = Callable[..., subprocess.CompletedProcess[str]]


def _circle(path: Path, n: int = 80, noise: float = 0.0) -> Path:
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    P = np.column_stack([np.cos(t), np.sin(t), np.zeros(n)])
    P[:, :2] += noise * np.random.default_rng(0).normal(size=(n, 2))
    lines = [f"v {x:.9f} {y:.9f} {z:.9f}" for x, y, z in P]
    lines.append("l " + " ".join(str(i + 1) for i in range(n)) + " 1")
    path.write_text("\n".join(lines) + "\n")
    return path


def test_strict_shape_loss_exits_12_and_writes_nothing(cli: Run, tmp_path: Path) -> None:
    src = _circle(tmp_path / "c.obj", noise=0.01)
    out, report = tmp_path / "o.obj", tmp_path / "r.json"
    res = cli(["smooth", src, "-o", out, "--rms", "0.5", "--strict", "--report", report])
    assert res.returncode == EXIT_SHAPE, res.stderr
    assert "lost shape" in res.stderr and "lower rms" in res.stderr
    assert not out.exists() and not report.exists()
    res = cli(["smooth", src, "-o", out, "--rms", "0.5", "--report", report])  # not strict
    assert res.returncode == EXIT_OK, res.stderr
    assert json.loads(report.read_text())["shape_warnings"]


def test_noise_free_input_says_so_and_is_written_unchanged(cli: Run, tmp_path: Path) -> None:
    src = _circle(tmp_path / "clean.obj")
    out, report = tmp_path / "o.obj", tmp_path / "r.json"
    res = cli(["smooth", src, "-o", out, "--report", report, "--strict"])
    assert res.returncode == EXIT_OK, res.stderr
    assert "no noise found" in res.stderr
    rep = json.loads(report.read_text())
    assert rep["noise_found"] is False and rep["rms_displacement"] == 0.0 and rep["tau"] is None
    written = [ln for ln in out.read_text().splitlines() if ln.startswith("v ")]
    original = [ln for ln in src.read_text().splitlines() if ln.startswith("v ")]
    assert np.array_equal(np.array([ln.split()[1:] for ln in written], dtype=float),
                          np.array([ln.split()[1:] for ln in original], dtype=float))
