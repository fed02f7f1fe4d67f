"""The use case read -> smooth -> write (service.workflows.smooth_file), tested directly."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from service.core import SmoothingParams
from service.io import FormatError, read_geometry
from service.io.dispatch import OutputRefused
from service.workflows import smooth_file as wf

PARAMS = SmoothingParams(tau=2.0, tile_points=1000)


def terrain_cloud(n: int, side: float, seed: int) -> np.ndarray:
    """``n`` scattered points on a gently curved ``side x side`` terrain with some noise."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0.0, side, (n, 2))
    z = 0.3 * np.sin(xy[:, 0] / 3.0) * np.cos(xy[:, 1] / 4.0) + rng.normal(0.0, 0.05, n)
    return np.c_[xy, z]


def _ply(path: Path, P: np.ndarray) -> Path:
    """A binary little-endian PLY point cloud (float32 x, y, z and a uchar label)."""
    head = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {len(P)}\nproperty float x\nproperty float y\nproperty float z\n"
        "property uchar label\nend_header\n"
    )
    rec = np.zeros(len(P), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("label", "u1")])
    rec["x"], rec["y"], rec["z"] = P[:, 0], P[:, 1], P[:, 2]
    rec["label"] = np.arange(len(P)) % 7
    path.write_bytes(head.encode() + rec.tobytes())
    return path


def _xyz(path: Path, P: np.ndarray) -> Path:
    path.write_text("".join(f"{x:.4f} {y:.4f} {z:.4f}\n" for x, y, z in P))
    return path


def _leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".tmp"))


@pytest.mark.parametrize("writer", [_ply, _xyz])
def test_streamed_and_in_memory_write_the_same_bytes(tmp_path: Path, writer: Any) -> None:
    fmt = writer.__name__[1:]
    src = writer(tmp_path / f"in.{fmt}", terrain_cloud(2500, side=30.0, seed=3))
    streamed = wf.smooth_file(src, tmp_path / f"streamed.{fmt}", PARAMS)
    assert streamed.streamed and streamed.document is None
    kept: dict[str, bytes] = {}
    in_memory = wf.smooth_file(src, lambda _r, data: kept.setdefault("data", data), PARAMS,
                               fmt=fmt)  # fmt: skip
    assert not in_memory.streamed and in_memory.document is not None
    assert in_memory.result.tiles is not None and in_memory.result.tiles["count"] > 1
    np.testing.assert_array_equal(streamed.result.points, in_memory.result.points)
    # the PLY writer signs the header it writes; the streamed path keeps the input's header
    written = kept["data"].replace(b"comment written by geosmooth\n", b"", 1)
    assert (tmp_path / f"streamed.{fmt}").read_bytes() == written


def test_untiled_runs_in_memory_to_a_file(tmp_path: Path) -> None:
    src = _xyz(tmp_path / "in.xyz", terrain_cloud(400, side=10.0, seed=4))
    dst = tmp_path / "out.xyz"
    done = wf.smooth_file(src, dst, SmoothingParams(tau=1.0))
    assert not done.streamed and (done.input_format, done.output_format) == ("xyz", "xyz")
    again = read_geometry(dst, "xyz").geometry.points
    np.testing.assert_allclose(again, done.result.points, atol=5e-5)
    assert _leftovers(tmp_path) == []


def test_a_failed_streamed_write_leaves_the_old_file(tmp_path: Path, monkeypatch: Any) -> None:
    src = _ply(tmp_path / "in.ply", terrain_cloud(2500, side=30.0, seed=3))
    dst = tmp_path / "out.ply"
    dst.write_bytes(b"the old file")

    def half(src: Path, dst: Path, fmt: str, points: np.ndarray) -> None:
        Path(dst).write_bytes(b"ply\nhalf a file")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr("service.io.stream.rewrite", half)
    with pytest.raises(OSError, match="No space left"):
        wf.smooth_file(src, dst, PARAMS)
    assert dst.read_bytes() == b"the old file"
    assert _leftovers(tmp_path) == []


def test_a_failed_encoding_writes_nothing(tmp_path: Path, monkeypatch: Any) -> None:
    src = _xyz(tmp_path / "in.xyz", terrain_cloud(300, side=10.0, seed=5))
    dst = tmp_path / "out.xyz"

    def refuse(*args: Any, **kwargs: Any) -> bytes:
        raise FormatError("coordinate 1e300 does not fit", fmt="xyz", line=7)

    monkeypatch.setattr("service.io.write_geometry", refuse)
    with pytest.raises(wf.OutputFormatError) as err:
        wf.smooth_file(src, dst, SmoothingParams(tau=1.0))
    exc = err.value
    assert isinstance(exc, FormatError) and exc.target_fmt == "xyz"
    assert (exc.message, exc.fmt, exc.line, exc.code, exc.status) == (
        "coordinate 1e300 does not fit", "xyz", 7, "format-error", 400
    )
    assert not dst.exists() and _leftovers(tmp_path) == []


def test_refused_output_formats_keep_their_class_and_cost_no_solve(
    tmp_path: Path, monkeypatch: Any
) -> None:
    """A mesh cannot be written as GPX: refused before the engine runs (OutputRefused)."""
    src = tmp_path / "in.obj"
    src.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0.2\nf 1 2 3\nf 2 4 3\n")
    calls: list[int] = []
    monkeypatch.setattr(wf, "run_engine", lambda *a, **k: calls.append(1))
    with pytest.raises(OutputRefused):
        wf.smooth_file(src, tmp_path / "out.gpx", SmoothingParams(tau=0.01), out_fmt="gpx")
    assert calls == [] and not (tmp_path / "out.gpx").exists()


def test_stages_and_check_in_order(tmp_path: Path) -> None:
    src = _xyz(tmp_path / "in.xyz", terrain_cloud(300, side=10.0, seed=6))
    seen: list[str] = []
    wf.smooth_file(src, lambda _r, _d: seen.append("stored"), SmoothingParams(tau=1.0),
                   stage=seen.append, check=lambda g: seen.append(f"check {g.n}"),
                   engine=lambda g: seen.append("engine") or wf.run_engine(
                       g, SmoothingParams(tau=1.0)))  # fmt: skip
    assert seen == ["reading", "check 300", "engine", "writing", "stored"]


def test_writer_options_or_a_store_keep_tiles_in_memory(tmp_path: Path) -> None:
    src = _xyz(tmp_path / "in.xyz", terrain_cloud(300, side=10.0, seed=6))
    out = tmp_path / "o.xyz"
    assert wf.streamed_format_of(src, out, PARAMS) == "xyz"
    assert wf.streamed_format_of(src, out, PARAMS, options={"precision": "float64"}) is None
    assert wf.streamed_format_of(src, lambda r, d: None, PARAMS) is None
    assert wf.streamed_format_of(src, out, SmoothingParams(tau=1.0)) is None
    assert wf.streamed_format_of(src, out, PARAMS, out_fmt="ply") is None


def test_the_cli_states_the_mapped_errors(tmp_path: Path, monkeypatch: Any, capsys: Any) -> None:
    """One mapping for both paths: an output format that cannot hold the points is exit
    status 6 (``cannot write <fmt>``), a tau out of range names the option and its range."""
    from service.cli.main import main

    src = _xyz(tmp_path / "in.xyz", terrain_cloud(300, side=10.0, seed=7))
    dst = tmp_path / "out.xyz"
    assert main(["smooth", str(src), "-o", str(dst), "--tau", "1e9", "-q"]) == 4
    assert "--tau 1e+09 is out of range for this input" in capsys.readouterr().err

    def refuse(*args: Any, **kwargs: Any) -> bytes:
        raise FormatError("x does not fit the scale", fmt="xyz")

    monkeypatch.setattr("service.io.write_geometry", refuse)
    assert main(["smooth", str(src), "-o", str(dst), "--tau", "1", "-q"]) == 6
    err = capsys.readouterr().err
    assert err == "geosmooth: error: cannot write xyz: x does not fit the scale\n"
    assert not dst.exists() and _leftovers(tmp_path) == []
