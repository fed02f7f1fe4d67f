"""``tile_points`` through the library, the CLI and the report."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import geosmooth
from service.core import Geometry, SmoothingParams, smooth
from tests.core.tiles.terrain import terrain_cloud


def _relative(a: np.ndarray, b: np.ndarray, P: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1)))
                 / np.sqrt(np.mean(np.sum((b - P) ** 2, axis=1))))  # fmt: skip


@pytest.fixture(scope="module")
def cloud() -> np.ndarray:
    return terrain_cloud(12000, side=50.0, seed=4)


def test_library_tile_points(cloud: np.ndarray) -> None:
    ref = smooth(Geometry(cloud), SmoothingParams(tau=60.0))
    out, res = geosmooth.smooth(cloud, tau=60.0, tile_points=3000, full_output=True)
    assert res.tiles is not None and res.tiles["count"] == 4
    assert sum(t["points"] for t in res.tiles["tiles"]) == cloud.shape[0]
    assert abs(res.phi - 60.0) / 60.0 <= 1e-3
    assert _relative(out, ref.points, cloud) <= 1e-2
    report = res.report()
    assert report["tiles"]["tiles"][0]["worker"].startswith("pid ")
    json.dumps(report)  # JSON-ready
    # below the tile size: the untiled pipeline, no tiles member
    small = smooth(Geometry(cloud[:2000]), SmoothingParams(tau=10.0, tile_points=3000))
    assert small.tiles is None


def test_cli_tile_points(cloud: np.ndarray, tmp_path: Path) -> None:
    src = tmp_path / "terrain.xyz"
    np.savetxt(src, cloud, fmt="%.6f")
    out = tmp_path / "out.xyz"
    rep = tmp_path / "report.json"
    exe = Path(sys.executable).with_name("geosmooth")
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[3])}
    proc = subprocess.run(
        [str(exe), "smooth", str(src), "-o", str(out), "--tau", "60", "--tile-points", "3000",
         "--report", str(rep), "-q"],
        capture_output=True, text=True, env=env, timeout=600, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    report = json.loads(rep.read_text())
    assert report["tiles"]["count"] == 4
    X = np.loadtxt(out)
    phi = float(np.sum((X - np.loadtxt(src)) ** 2))
    assert abs(phi - 60.0) / 60.0 <= 2e-3  # the file's 6 decimals


def test_cli_refuses_tiles_with_a_global_option(cloud: np.ndarray, tmp_path: Path) -> None:
    src = tmp_path / "terrain.xyz"
    np.savetxt(src, cloud[:3000], fmt="%.6f")
    exe = Path(sys.executable).with_name("geosmooth")
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[3])}
    proc = subprocess.run(
        [str(exe), "smooth", str(src), "-o", str(tmp_path / "o.xyz"), "--tile-points", "1000",
         "--preserve-volume"],
        capture_output=True, text=True, env=env, timeout=600, check=False,
    )  # fmt: skip
    assert proc.returncode != 0
    assert "preserve_volume" in proc.stderr and "Traceback" not in proc.stderr
