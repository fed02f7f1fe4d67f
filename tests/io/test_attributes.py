"""Nothing of the input is lost: attributes, UVs and face structure, colours, normals, precision."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from service.core import smooth
from service.core.params import SmoothingParams
from service.io import read_geometry, write_geometry
from service.io.formats.ply.read import PlyLayout
from tests.io.io_builders import ply_bytes


def _smoothed(doc, rms_fraction: float = 0.002):  # type: ignore[no-untyped-def]
    g = doc.geometry
    extent = float(np.max(np.ptp(g.points, axis=0)))
    return smooth(g, SmoothingParams(rms=rms_fraction * extent)).points


def test_spot_keeps_uvs_and_face_structure(data_dir: Path) -> None:
    raw = (data_dir / "spot.obj").read_bytes()
    doc = read_geometry(raw, "obj")
    pts = _smoothed(doc)
    out = write_geometry(doc, "obj", pts)
    lines_in, lines_out = raw.decode().splitlines(), out.decode().splitlines()
    # every vt and f line is the input's, in the same order
    for key in ("vt ", "f "):
        assert [x for x in lines_in if x.startswith(key)] == [
            x for x in lines_out if x.startswith(key)
        ]
    assert sum(x.startswith("vt ") for x in lines_out) == 3225
    back = read_geometry(out, "obj")
    assert back.geometry.n == 2930
    assert np.array_equal(back.geometry.faces, doc.geometry.faces)
    # coordinates moved, written with the input's digits (6 significant)
    assert np.abs(back.geometry.points - pts).max() <= 5e-6 * np.abs(pts).max()
    assert not np.array_equal(back.geometry.points, doc.geometry.points)
    assert len(out) / len(raw) <= 1.05


def test_fandisk_vn_recomputed_per_corner(data_dir: Path) -> None:
    raw = (data_dir / "fandisk.obj").read_bytes()
    doc = read_geometry(raw, "obj")
    pts = _smoothed(doc)
    out = write_geometry(doc, "obj", pts).decode()
    vn = np.array([[float(t) for t in x.split()[1:]] for x in out.splitlines() if x[:3] == "vn "])
    vn_in = np.array(
        [[float(t) for t in x.split()[1:]] for x in raw.decode().splitlines() if x[:3] == "vn "]
    )
    assert vn.shape == vn_in.shape == (2877, 3)
    assert np.allclose(np.linalg.norm(vn, axis=1), 1.0, atol=1e-5)
    agree = np.einsum("ij,ij->i", vn, vn_in) > 0
    assert agree.mean() >= 0.99
    # normals="drop" removes vn lines and the //vn of the faces
    dropped = write_geometry(doc, "obj", pts, normals="drop").decode()
    assert "\nvn " not in dropped and "//" not in dropped
    assert read_geometry(dropped.encode(), "obj").geometry.faces.tolist() == (
        doc.geometry.faces.tolist()
    )


def test_coloured_cloud_keeps_colours(data_dir: Path) -> None:
    raw = (data_dir / "points_agisoft.xyz").read_bytes()
    doc = read_geometry(raw, "xyz")
    assert list(doc.attributes) == ["red", "green", "blue"]
    moved = doc.geometry.points + np.array([0.25, -0.125, 0.0625])
    out = write_geometry(doc, "xyz", moved)
    back = read_geometry(out, "xyz")
    for c in ("red", "green", "blue"):
        assert np.array_equal(back.attributes[c], doc.attributes[c])
    # colour columns come back as the same text, coordinates with the input's 6 decimals
    assert [ln.split()[3:] for ln in out.decode().splitlines()] == [
        ln.split()[3:] for ln in raw.decode().splitlines()
    ]
    assert np.abs(back.geometry.points - moved).max() <= 5e-7
    assert len(out) == len(raw)


def test_horse_colours_and_confidence_survive_smoothing(data_dir: Path) -> None:
    doc = read_geometry(data_dir / "horse.ply")
    assert list(doc.attributes) == ["confidence", "red", "green", "blue"]
    pts = _smoothed(doc)
    back = read_geometry(write_geometry(doc, "ply", pts), "ply")
    assert isinstance(back.layout, PlyLayout)
    assert back.layout.header.encoding == "binary_big_endian"  # the input's encoding
    for name, values in doc.attributes.items():
        assert back.attributes[name].dtype == values.dtype
        assert np.array_equal(back.attributes[name], values)
    assert np.array_equal(back.geometry.points, pts.astype(np.float32).astype(np.float64))


def test_bun_zipper_normals_recomputed_and_oriented(data_dir: Path) -> None:
    trimesh = pytest.importorskip("trimesh")
    src = read_geometry(data_dir / "bun_zipper.ply")
    mesh = trimesh.Trimesh(src.geometry.points, src.geometry.faces, process=False)
    normals = np.asarray(mesh.vertex_normals, dtype=np.float32)
    props = [("float", c) for c in ("x", "y", "z", "nx", "ny", "nz")]
    data = ply_bytes(
        "binary_little_endian",
        props,
        np.column_stack([src.geometry.points, normals]),
        src.geometry.faces.tolist(),
    )
    doc = read_geometry(data, "ply")
    assert doc.normals is not None and doc.normals.dtype == np.float32
    pts = _smoothed(doc, 0.001)
    back = read_geometry(write_geometry(doc, "ply", pts), "ply")
    new = back.normals.astype(np.float64)
    assert np.abs(np.linalg.norm(new, axis=1) - 1).max() < 1e-6
    # the 1113 vertices in no face have no input normal (trimesh gives 0) to agree with
    has_input = np.linalg.norm(normals, axis=1) > 0
    assert has_input.mean() > 0.96
    agree = np.einsum("ij,ij->i", new, normals) > 0
    assert agree[has_input].mean() >= 0.99
    assert not np.array_equal(new, normals)  # recomputed, not copied
    dropped = read_geometry(write_geometry(doc, "ply", pts, normals="drop"), "ply")
    assert dropped.normals is None


def test_cloud_normals_from_neighbourhoods(data_dir: Path) -> None:
    src = read_geometry(data_dir / "bun_zipper.ply")
    trimesh = pytest.importorskip("trimesh")
    normals = trimesh.Trimesh(src.geometry.points, src.geometry.faces, process=False)
    used = np.unique(src.geometry.faces)
    pts, nrm = src.geometry.points[used], np.asarray(normals.vertex_normals)[used]
    rows = np.column_stack([pts, nrm]).tolist()
    text = "\n".join(" ".join(repr(v) for v in row) for row in rows)
    doc = read_geometry(text.encode(), "xyz")
    assert doc.normals is not None and not doc.attributes
    back = read_geometry(write_geometry(doc, "xyz", pts * 1.0 + 1e-6), "xyz")
    new = back.normals
    assert np.abs(np.linalg.norm(new, axis=1) - 1).max() < 1e-5
    cosines = np.einsum("ij,ij->i", new, nrm)
    assert np.all(cosines > 0)  # oriented like the input, point by point
    assert np.median(cosines) > 0.98  # and the PCA plane agrees with the surface


@pytest.mark.parametrize("name", ["bun_zipper.ply", "turbineblade.ply", "bun000.ply"])
def test_float32_stays_float32(data_dir: Path, name: str) -> None:
    raw = (data_dir / name).read_bytes()
    doc = read_geometry(raw, "ply")
    assert doc.precision.dtype == "float32"
    out = write_geometry(doc, "ply", doc.geometry.points * 1.5)
    header = out.split(b"end_header")[0].decode()
    assert "property float x" in header and "double" not in header
    as64 = write_geometry(doc, "ply", doc.geometry.points * 1.5, precision="float64")
    assert "property double x" in as64.split(b"end_header")[0].decode()


def test_ascii_ply_keeps_digits_and_elements(data_dir: Path) -> None:
    raw = (data_dir / "bun000.ply").read_bytes()
    doc = read_geometry(raw, "ply")
    out = write_geometry(doc, "ply")
    head_in, head_out = raw.split(b"end_header")[0], out.split(b"end_header")[0]
    assert re.findall(rb"element \w+ \d+", head_in) == re.findall(rb"element \w+ \d+", head_out)
    assert b"obj_info" in head_out
    back = read_geometry(out, "ply")
    assert np.array_equal(back.geometry.points, doc.geometry.points)
    assert len(out) / len(raw) <= 1.05


def test_json_carries_attributes_and_normals(data_dir: Path) -> None:
    doc = read_geometry(data_dir / "horse.ply")
    text = write_geometry(doc, "json")  # float32 points in their shortest text
    back = read_geometry(text, "json")
    for name, values in doc.attributes.items():
        assert back.attributes[name].dtype == values.dtype.newbyteorder("=")
        assert np.array_equal(back.attributes[name], values)
    assert np.array_equal(back.geometry.points.astype(np.float32), doc.geometry.points)
    assert len(text) < len(write_geometry(doc, "json", precision="float64"))
    again = read_geometry(write_geometry(back, "ply"), "ply")
    assert np.array_equal(again.attributes["red"], doc.attributes["red"])
    assert again.precision.dtype == "float32"  # JSON remembered the input's precision
