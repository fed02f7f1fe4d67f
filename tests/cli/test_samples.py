"""The bundled synthetic samples: known ground truth, so smoothing must move toward it."""

from __future__ import annotations

import json
import subprocess
from collections.abc import Callable
from pathlib import Path

import numpy as np

from service.io import read_geometry
from service.samples.generate import HELIX_SIGMA, SPHERE_SIGMA, helix, icosphere, main

Run = Callable[..., subprocess.CompletedProcess[str]]
SAMPLES = Path(__file__).resolve().parents[2] / "service" / "samples"


def test_noisy_sphere_moves_toward_the_sphere(cli: Run, tmp_path: Path):
    src, out, rep = SAMPLES / "noisy-sphere.ply", tmp_path / "sphere.ply", tmp_path / "r.json"
    _, faces = icosphere(3)
    noisy = read_geometry(src).geometry
    np.testing.assert_array_equal(noisy.faces, faces)
    tau = noisy.n * 3 * SPHERE_SIGMA**2  # tau ~ n * s * sigma^2
    res = cli(["smooth", src, "-o", out, "--tau", tau, "--preserve-volume", "--report", rep])
    assert res.returncode == 0, res.stderr
    x = read_geometry(out).geometry.points
    # Only the noise along the normal changes the shape: the distance to the sphere must drop.
    radial_before = np.abs(np.linalg.norm(noisy.points, axis=1) - 1).mean()
    radial_after = np.abs(np.linalg.norm(x, axis=1) - 1).mean()
    assert radial_after < 0.5 * radial_before
    assert json.loads(rep.read_text())["volume_scale"] is not None


def test_noisy_helix_moves_toward_the_helix(cli: Run, tmp_path: Path):
    src, out = SAMPLES / "noisy-helix.obj", tmp_path / "helix.obj"
    truth = helix(200)
    noisy = read_geometry(src)
    assert len(noisy.polylines) == 1 and noisy.geometry.n == 200
    res = cli(["smooth", src, "-o", out, "--rms", HELIX_SIGMA * 3**0.5, "--quiet"])
    assert res.returncode == 0, res.stderr
    assert res.stderr == ""
    x = read_geometry(out).geometry.points
    err_before = np.linalg.norm(noisy.geometry.points - truth, axis=1).mean()
    err_after = np.linalg.norm(x - truth, axis=1).mean()
    assert err_after < 0.7 * err_before


def test_shipped_samples_are_what_the_generator_makes(tmp_path: Path):
    main(tmp_path)
    for name in ("noisy-sphere.ply", "noisy-helix.obj"):
        assert (tmp_path / name).read_bytes() == (SAMPLES / name).read_bytes(), name
