"""Every PLY/OBJ/XYZ file of the shared real data loads with the counts of MANIFEST.md."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from service.io import read_geometry, write_geometry

# file -> (vertices, faces) as the file declares them (MANIFEST.md)
MANIFEST = {
    "bun_zipper_res4.ply": (453, 948),
    "bunny.ply": (8171, 16301),
    "bun_zipper.ply": (35947, 69451),
    "spot.obj": (2930, 5856),
    "fandisk.obj": (2877, 5750),
    "featuretype.ply": (5096, 3476),
    "horse.ply": (48485, 96966),
    "turbineblade.ply": (99519, 199034),
    "bun000.ply": (40256, 0),
    "bun000_rangegrid_tri.ply": (40256, 77204),
    "blackVase_decimated.ply": (17337, 31366),
    "table_scene_mug_stereo_textured.xyz": (209280, 0),
    "points_agisoft.xyz": (100, 0),
    "korita-zbevnica.obj": (871, 0),
    "ne_110m_coastline.obj": (5008, 0),
}


@pytest.mark.parametrize("name", sorted(MANIFEST))
def test_manifest_counts(data_dir: Path, name: str) -> None:
    n, m = MANIFEST[name]
    doc = read_geometry(data_dir / name, weld=False)  # as the file declares them
    g = doc.geometry
    assert g.n == n
    assert g.dim == 3
    assert g.points.dtype == np.float64
    assert (0 if g.faces is None else len(g.faces)) == m
    assert doc.source_format == name.rsplit(".", 1)[1]
    assert doc.weld is None and doc.n_output == n


def test_bun000_is_a_cloud_and_range_grid_is_skipped(data_dir: Path) -> None:
    doc = read_geometry(data_dir / "bun000.ply")
    assert doc.geometry.kind == "cloud"
    assert doc.geometry.n == 40256
    assert any("range_grid" in note and "204800" in note for note in doc.notes)


def test_bun000_and_its_triangulation_share_vertices(data_dir: Path) -> None:
    ascii_doc = read_geometry(data_dir / "bun000.ply")
    binary_doc = read_geometry(data_dir / "bun000_rangegrid_tri.ply")
    # same float32 values, one file ascii, the other binary
    assert np.array_equal(ascii_doc.geometry.points, binary_doc.geometry.points)


def test_korita_polylines(data_dir: Path) -> None:
    doc = read_geometry(data_dir / "korita-zbevnica.obj")
    assert doc.geometry.kind == "curve"
    assert len(doc.polylines) == 3
    assert not any(p.closed for p in doc.polylines)
    assert sum(len(p) for p in doc.polylines) == 871
    assert len(doc.geometry.edges) == 871 - 3


def test_coastline_polylines(data_dir: Path) -> None:
    doc = read_geometry(data_dir / "ne_110m_coastline.obj")
    assert len(doc.polylines) == 134
    assert sum(p.closed for p in doc.polylines) == 120
    # closed rings are stored once, without repeating their first vertex
    for p in doc.polylines:
        assert p.indices[0] != p.indices[-1]
    assert np.all(doc.geometry.points[:, 2] == 0.0)


def test_featuretype_welds_to_1722(data_dir: Path) -> None:
    doc = read_geometry(data_dir / "featuretype.ply", weld=True)
    assert doc.geometry.n == 1722
    assert doc.weld is not None and doc.weld.n_original == 5096
    assert doc.n_output == 5096
    assert doc.geometry.faces is not None and len(doc.geometry.faces) == 3476
    assert np.array_equal(
        doc.geometry.points[doc.weld.index],
        read_geometry(data_dir / "featuretype.ply", weld=False).geometry.points,
    )


def test_featuretype_welds_by_default_and_its_copies_stay_together(
    data_dir: Path, tmp_path: Path
) -> None:
    """Issue 31: duplicate positions that tie faces are welded by default (any format); with
    rms 0.01 the copies of each vertex end identical, the file's 5096 vertices in order."""
    from service.core.params import SmoothingParams
    from service.io._shared.weld import weld_index
    from service.workflows.smooth_file import smooth_file

    src = data_dir / "featuretype.ply"
    doc = read_geometry(src)
    assert doc.weld is not None and doc.geometry.n == 1722 and doc.n_output == 5096
    assert any("3374 duplicate positions tie faces" in n for n in doc.notes)
    smooth_file(src, tmp_path / "out.ply", SmoothingParams(rms=0.01))
    raw = read_geometry(src, weld=False)
    out = read_geometry(tmp_path / "out.ply", weld=False)
    assert out.geometry.n == 5096 and np.array_equal(out.geometry.faces, raw.geometry.faces)
    index, _ = weld_index(raw.geometry.points)  # copies grouped from the input, independently
    P = out.geometry.points
    for group in np.unique(index)[:: 50]:
        members = np.flatnonzero(index == group)
        assert np.all(P[members] == P[members[0]])
    assert not np.array_equal(P, raw.geometry.points)  # it was smoothed
    apart = smooth_file(src, tmp_path / "apart.ply", SmoothingParams(rms=0.01),
                        read_options={"weld": False})
    Q = read_geometry(tmp_path / "apart.ply", weld=False).geometry.points
    gaps = [np.ptp(Q[index == g], axis=0).max() for g in np.unique(index)]
    assert max(gaps) > 0.05 and apart.document is not None and apart.document.weld is None


def test_duplicates_without_faces_are_not_welded() -> None:
    P = np.array([[0.0, 0, 0], [1, 0, 0], [1, 0, 0], [0, 1, 0]])
    text = "\n".join(" ".join(map(str, p)) for p in P).encode()
    doc = read_geometry(text, "xyz")
    assert doc.weld is None and doc.geometry.n == 4


def test_points_agisoft_keeps_full_coordinates(data_dir: Path) -> None:
    doc = read_geometry(data_dir / "points_agisoft.xyz")
    assert doc.geometry.points[0].tolist() == [665187.522077, 5648349.895035, 241.767693]
    assert any("3 extra columns" in note for note in doc.notes)


@pytest.mark.parametrize("name", ["horse.ply", "bunny.ply", "turbineblade.ply"])
def test_vertices_match_trimesh(data_dir: Path, name: str) -> None:
    trimesh = pytest.importorskip("trimesh")
    ours = read_geometry(data_dir / name).geometry
    theirs = trimesh.load(data_dir / name, process=False)
    assert np.array_equal(ours.points, np.asarray(theirs.vertices, dtype=np.float64))
    assert np.array_equal(ours.faces, np.asarray(theirs.faces))


@pytest.mark.parametrize("name", ["horse.ply", "turbineblade.ply"])
def test_binary_ply_is_fast(data_dir: Path, name: str) -> None:
    data = (data_dir / name).read_bytes()
    read_geometry(data, "ply")  # warm-up (imports, page cache)
    start = time.process_time()  # CPU time: what the reader costs, whatever the load
    read_geometry(data, "ply")
    assert time.process_time() - start < 1.0


def test_spot_ignores_texture_coordinates(data_dir: Path) -> None:
    doc = read_geometry(data_dir / "spot.obj")
    assert doc.geometry.n == 2930  # no UV-seam split, unlike trimesh's 3225
    assert doc.geometry.faces is not None and doc.geometry.faces.max() < 2930


SHARED = [*sorted(MANIFEST), "korita-zbevnica.gpx", "ne_110m_coastline.geojson", "wrench.dxf"]


def _moved(points: np.ndarray) -> np.ndarray:
    """1e-4 of the extent in the coordinates that vary (as smoothing moves them)."""
    spread = np.ptp(points, axis=0)
    noise = np.random.default_rng(0).normal(size=points.shape)
    return points + noise * 1e-4 * float(spread.max()) * (spread > 0)


@pytest.mark.parametrize("name", SHARED)
def test_shared_file_round_trip(data_dir: Path, name: str) -> None:
    """Written back in its own format: everything read comes back, and the size stays."""
    raw = (data_dir / name).read_bytes()
    doc = read_geometry(raw, filename=name)
    back = read_geometry(write_geometry(doc, doc.source_format), doc.source_format)
    assert back.geometry.points.tobytes() == doc.geometry.points.tobytes()
    assert list(back.attributes) == list(doc.attributes)
    for key, values in doc.attributes.items():
        assert back.attributes[key].dtype == values.dtype, key
        assert back.attributes[key].tobytes() == values.tobytes(), key
    for part in ("faces", "edges"):
        a, b = getattr(doc.geometry, part), getattr(back.geometry, part)
        assert (a is None and b is None) or np.array_equal(a, b), part
    assert [(p.indices.tolist(), p.closed) for p in back.polylines] == [
        (p.indices.tolist(), p.closed) for p in doc.polylines
    ]
    if doc.normals is not None:
        assert np.array_equal(back.normals, doc.normals)
    moved = write_geometry(doc, doc.source_format, _moved(doc.geometry.points))
    assert len(moved) / len(raw) <= 1.05
