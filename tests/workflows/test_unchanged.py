"""Unchanged is byte-identical (issue 32): when nothing is smoothed the output is the input's
bytes in its own format, or a straight conversion across formats, and the result says which.

Reads the shared data set (``$GEOSMOOTH_SHARED_DATA`` or ``../shared/data``); nothing of it is
copied into the repository (outputs go to ``tmp_path``).
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from service.core import SmoothingParams
from service.core.geometry import Geometry
from service.io import read_geometry
from service.workflows import smooth_file as wf

REPO = Path(__file__).resolve().parents[2]
SHARED = Path(os.environ.get("GEOSMOOTH_SHARED_DATA") or REPO.parent / "shared" / "data")
needs_shared = pytest.mark.skipif(
    not SHARED.is_dir(), reason="shared data not found (set GEOSMOOTH_SHARED_DATA)"
)

#: One shared file per format the shared data come in (the smallest of each).
BY_FORMAT = {
    "ply": "bun_zipper_res4.ply",
    "obj": "korita-zbevnica.obj",
    "xyz": "points_agisoft.xyz",
    "gpx": "korita-zbevnica.gpx",
    "geojson": "ne_110m_coastline.geojson",
    "dxf": "wrench.dxf",
}
LAM = SmoothingParams(lam=1.0)


def _all_fixed(path: Path) -> tuple[Any, Geometry]:
    """The document of ``path`` and its geometry with every point fixed (nothing can move)."""
    doc = read_geometry(path)
    g = doc.geometry
    return doc, dataclasses.replace(g, fixed=np.arange(g.n, dtype=np.int64))


@needs_shared
@pytest.mark.parametrize("fmt", sorted(BY_FORMAT))
def test_every_shared_format_comes_back_byte_identical(tmp_path: Path, fmt: str) -> None:
    src = SHARED / BY_FORMAT[fmt]
    doc, fixed = _all_fixed(src)
    out = tmp_path / f"out.{fmt}"
    done = wf.smooth_file(doc, out, LAM, geometry=fixed, original=src)
    assert done.unchanged == wf.COPIED and done.result.report()["unchanged"] == "copied"
    assert done.summary == "returned unchanged: input bytes copied"
    assert out.read_bytes() == src.read_bytes(), (fmt, src.stat().st_size, out.stat().st_size)


@needs_shared
def test_bunny_with_no_noise_keeps_its_658744_bytes(tmp_path: Path) -> None:
    src, out = SHARED / "bunny.ply", tmp_path / "bunny.ply"
    done = wf.smooth_file(src, out, SmoothingParams())
    assert done.result.noise_found is False
    assert done.unchanged == wf.COPIED
    assert out.stat().st_size == src.stat().st_size == 658_744
    assert out.read_bytes() == src.read_bytes()


@needs_shared
def test_wrench_keeps_its_lines_and_arcs(tmp_path: Path) -> None:
    ezdxf = pytest.importorskip("ezdxf")
    src, out = SHARED / "wrench.dxf", tmp_path / "wrench.dxf"
    done = wf.smooth_file(src, out, SmoothingParams())
    assert done.result.noise_found is False and done.unchanged == wf.COPIED
    msp = ezdxf.readfile(out).modelspace()
    assert len(msp.query("LINE")) == 35 and len(msp.query("ARC")) == 4
    assert len(msp.query("LWPOLYLINE")) == 0
    assert out.read_bytes() == src.read_bytes()


@needs_shared
def test_across_formats_a_straight_conversion(tmp_path: Path) -> None:
    src = SHARED / "korita-zbevnica.gpx"
    doc, fixed = _all_fixed(src)
    out = tmp_path / "out.geojson"
    done = wf.smooth_file(doc, out, LAM, geometry=fixed, out_fmt="geojson", original=src)
    assert done.unchanged == wf.CONVERTED and done.summary == "converted unchanged"
    assert done.result.report()["unchanged"] == "converted"
    assert out.read_bytes() == wf.encode(doc, "geojson")  # the input's points, converted
    back = read_geometry(out).geometry.points
    np.testing.assert_allclose(back[:, :2], doc.geometry.points[:, :2], rtol=0, atol=1e-6)


@needs_shared
def test_writer_options_or_no_input_bytes_convert(tmp_path: Path) -> None:
    src = SHARED / "bun_zipper_res4.ply"
    doc, fixed = _all_fixed(src)
    asked = wf.smooth_file(doc, tmp_path / "a.ply", LAM, geometry=fixed, original=src,
                           write_options={"ply_ascii": True})  # fmt: skip
    assert asked.unchanged == wf.CONVERTED
    unknown = wf.smooth_file(doc, tmp_path / "b.ply", LAM, geometry=fixed)  # no bytes at hand
    assert unknown.unchanged == wf.CONVERTED
    assert (tmp_path / "b.ply").read_bytes() == wf.encode(doc, "ply")


@needs_shared
def test_callable_target_gets_the_input_bytes(tmp_path: Path) -> None:
    src = SHARED / "points_agisoft.xyz"
    doc, fixed = _all_fixed(src)
    got: dict[str, Any] = {}
    done = wf.smooth_file(doc, lambda r, data: got.update(result=r, data=data), LAM,
                          geometry=fixed, original=src.read_bytes())  # fmt: skip
    assert got["data"] == src.read_bytes() and got["result"].unchanged == "copied"
    assert done.unchanged == wf.COPIED


def test_smoothed_output_is_not_marked(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    P = np.c_[np.linspace(0, 10, 200), np.sin(np.linspace(0, 10, 200)) + rng.normal(0, 0.05, 200)]
    src = tmp_path / "in.xyz"
    src.write_text("".join(f"{x:.5f} {y:.5f}\n" for x, y in P))
    done = wf.smooth_file(src, tmp_path / "out.xyz", SmoothingParams(rms=0.02))
    assert done.unchanged is None and done.summary is None
    assert done.result.report()["unchanged"] is None
    assert (tmp_path / "out.xyz").read_bytes() != src.read_bytes()


def test_streamed_unchanged_copies_the_file(tmp_path: Path, monkeypatch: Any) -> None:
    rng = np.random.default_rng(2)
    P = np.c_[rng.uniform(0, 30, (2500, 2)), rng.normal(0, 0.05, 2500)]
    src = tmp_path / "in.xyz"
    src.write_text("".join(f"{x:.4f}  {y:.4f}  {z:.4f} \n" for x, y, z in P))  # odd spacing
    real = wf.run_engine

    def nothing_moves(g: Geometry, *_a: Any, **_k: Any) -> Any:
        return real(dataclasses.replace(g, fixed=np.arange(g.n, dtype=np.int64)), LAM)

    monkeypatch.setattr(wf, "run_engine", nothing_moves)
    out = tmp_path / "out.xyz"
    done = wf.smooth_file(src, out, SmoothingParams(tau=2.0, tile_points=1000))
    assert done.streamed and done.unchanged == wf.COPIED
    assert out.read_bytes() == src.read_bytes()


@needs_shared
def test_facade_smooth_file_copies_too(tmp_path: Path) -> None:
    import geosmooth

    src, out = SHARED / "wrench.dxf", tmp_path / "w.dxf"
    result = geosmooth.smooth_file(src, out)
    assert result.unchanged == "copied" and out.read_bytes() == src.read_bytes()


@needs_shared
def test_a_bad_crs_is_refused_before_smoothing(tmp_path: Path, monkeypatch: Any) -> None:
    from service.core.errors import ParameterError

    monkeypatch.setattr(wf, "run_engine", lambda *a, **k: pytest.fail("smoothed"))
    src = SHARED / "korita-zbevnica.gpx"
    for out_fmt, crs, words in (("dxf", 4326, "not a projected CRS"), ("gpx", "utm", "projected"),
                                ("dxf", "mercator", "EPSG code")):  # fmt: skip
        with pytest.raises(ParameterError, match=words) as caught:
            wf.smooth_file(src, tmp_path / f"o.{out_fmt}", LAM, out_fmt=out_fmt,
                           write_options={"crs": crs})  # fmt: skip
        assert caught.value.field == "crs"
    assert not list(tmp_path.iterdir())
