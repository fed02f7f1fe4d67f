"""Write then read: points bit-identical, connectivity kept, in every format."""

from __future__ import annotations

import numpy as np
import pytest

from service.core.geometry import Geometry
from service.io import (
    FORMATS,
    FormatError,
    GeometryDocument,
    read_geometry,
    write_geometry,
)
from service.io.dispatch import input_kinds, output_notes

# formats that store any float64 exactly (precision="float64"); the others are tested per
# format in test_io_formats.py with their own precision (float32, LAS scales, degrees, ...)
EXACT = ["ply", "obj", "xyz", "json", "off", "pcd"]


def _awkward_points(n: int, s: int, seed: int = 0) -> np.ndarray:
    """Points whose decimal forms need all 17 digits (plus some exact values)."""
    rng = np.random.default_rng(seed)
    pts = rng.standard_normal((n, s)) * 10.0 ** rng.integers(-8, 8, size=(n, s))
    pts[0] = 0.1
    pts[-1] = -0.0
    return pts


def _held(doc: GeometryDocument, fmt: str) -> GeometryDocument:
    """``doc``, or its points alone where ``fmt`` holds no faces/lines (XYZ, PCD: refused)."""
    if input_kinds(doc) <= FORMATS[fmt].kinds:
        return doc
    return GeometryDocument.from_geometry(Geometry(doc.geometry.points))


def _mesh_doc() -> GeometryDocument:
    text = (
        b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\nv 3 0 0\nv 3 1 0\n"
        b"f 1 2 3 4\nf 2 5 3\nl 5 6 7 5\nl 6 1\n"
    )
    doc = read_geometry(text, "obj")
    return doc.with_points(_awkward_points(doc.geometry.n, 3))


@pytest.mark.parametrize("fmt", EXACT)
def test_points_round_trip_bit_identical(fmt: str) -> None:
    doc = _held(_mesh_doc(), fmt)
    back = read_geometry(write_geometry(doc, fmt, precision="float64"), fmt)
    assert back.geometry.points.tobytes() == doc.geometry.points.tobytes()


@pytest.mark.parametrize("fmt", ["ply", "obj", "json"])
def test_connectivity_round_trip(fmt: str) -> None:
    doc = _mesh_doc()
    back = read_geometry(write_geometry(doc, fmt), fmt)
    assert np.array_equal(back.geometry.faces, doc.geometry.faces)
    assert np.array_equal(back.geometry.edges, doc.geometry.edges)


@pytest.mark.parametrize("fmt", ["obj", "json"])
def test_polylines_round_trip(fmt: str) -> None:
    doc = _mesh_doc()
    assert [(p.indices.tolist(), p.closed) for p in doc.polylines] == [
        ([4, 5, 6], True),
        ([5, 0], False),
    ]
    back = read_geometry(write_geometry(doc, fmt), fmt)
    assert [(p.indices.tolist(), p.closed) for p in back.polylines] == [
        ([4, 5, 6], True),
        ([5, 0], False),
    ]


def test_obj_writes_closed_polyline_with_repeated_first_index() -> None:
    text = write_geometry(_mesh_doc(), "obj").decode()
    assert "l 5 6 7 5\n" in text
    assert "f 1 2 3 4\nf 2 5 3\n" in text  # the file's own faces, not triangulated


def test_ply_writes_polylines_as_edges() -> None:
    doc = _mesh_doc()
    back = read_geometry(write_geometry(doc, "ply"), "ply")
    assert back.polylines == []
    assert np.array_equal(back.geometry.edges, doc.geometry.edges)


@pytest.mark.parametrize("ascii_ply", [False, True])
def test_ply_encodings(ascii_ply: bool) -> None:
    doc = _mesh_doc()
    data = write_geometry(doc, "ply", ply_ascii=ascii_ply, precision="float64")
    expected = b"format ascii 1.0" if ascii_ply else b"format binary_little_endian 1.0"
    assert expected in data.split(b"end_header")[0]
    back = read_geometry(data, "ply")
    assert np.array_equal(back.geometry.points, doc.geometry.points)
    assert np.array_equal(back.geometry.faces, doc.geometry.faces)


def test_xyz_writes_the_vertices_of_a_mesh_with_a_note() -> None:
    """Issue 32: a mesh to a point format writes its vertices (as PDAL does), and says so."""
    doc = _mesh_doc()
    back = read_geometry(write_geometry(doc, "xyz", precision="float64"), "xyz")
    assert np.array_equal(back.geometry.points, doc.geometry.points)
    assert back.geometry.faces is None
    note = f"XYZ keeps no faces or lines: wrote the {doc.n_output} vertices as points"
    assert note in output_notes(doc, "xyz")


@pytest.mark.parametrize("s", [1, 2, 5])
def test_json_any_dimension(s: int) -> None:
    doc = GeometryDocument.from_geometry(
        Geometry(_awkward_points(6, s, seed=s), edges=[[0, 1], [1, 2]])
    )
    back = read_geometry(write_geometry(doc, "json"), "json")
    assert back.geometry.dim == s
    assert np.array_equal(back.geometry.points, doc.geometry.points)
    assert np.array_equal(back.geometry.edges, doc.geometry.edges)


@pytest.mark.parametrize("s", [2, 5])
def test_xyz_any_dimension(s: int) -> None:
    doc = GeometryDocument.from_geometry(Geometry(_awkward_points(7, s, seed=s)))
    data = write_geometry(doc, "xyz")
    assert all(len(line.split()) == s for line in data.decode().splitlines())
    back = read_geometry(data, "xyz", xyz_dims=s)
    assert np.array_equal(back.geometry.points, doc.geometry.points)
    if s == 2:  # two columns read as 2D without help
        assert read_geometry(data, "xyz").geometry.dim == 2
    else:  # default: the first three columns
        assert np.array_equal(
            read_geometry(data, "xyz").geometry.points, doc.geometry.points[:, :3]
        )


@pytest.mark.parametrize("fmt", ["ply", "obj"])
def test_2d_points_get_z_zero(fmt: str) -> None:
    pts = _awkward_points(4, 2)
    doc = GeometryDocument.from_geometry(Geometry(pts, faces=[[0, 1, 2], [0, 2, 3]]))
    back = read_geometry(write_geometry(doc, fmt), fmt)
    assert np.array_equal(back.geometry.points[:, :2], pts)
    assert np.all(back.geometry.points[:, 2] == 0.0)


@pytest.mark.parametrize("fmt", ["ply", "obj"])
@pytest.mark.parametrize("s", [1, 4])
def test_ply_obj_refuse_other_dimensions(fmt: str, s: int) -> None:
    doc = GeometryDocument.from_geometry(Geometry(np.zeros((3, s))))
    with pytest.raises(FormatError, match=f"{s} coordinates per point.*write (xyz, )?json instead"):
        write_geometry(doc, fmt)


def test_xyz_refuses_1d() -> None:
    doc = GeometryDocument.from_geometry(Geometry(np.zeros((3, 1))))
    with pytest.raises(FormatError, match="at least 2"):
        write_geometry(doc, "xyz")


@pytest.mark.parametrize("fmt", EXACT)
def test_write_given_points(fmt: str) -> None:
    doc = _held(_mesh_doc(), fmt)
    moved = doc.geometry.points * 3.0 + 1e-9
    back = read_geometry(write_geometry(doc, fmt, moved, precision="float64"), fmt)
    assert np.array_equal(back.geometry.points, moved)


def test_write_rejects_points_of_wrong_shape() -> None:
    doc = _mesh_doc()
    with pytest.raises(ValueError, match="shape"):
        write_geometry(doc, "ply", np.zeros((3, 3)))


@pytest.mark.parametrize("fmt", EXACT)
def test_weld_round_trip_keeps_vertex_count_and_order(fmt: str) -> None:
    # two triangles sharing an edge, stored with split vertices (as STL exports do)
    text = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 4 5 6\n"
    doc = read_geometry(text, "obj", weld=True)
    assert doc.geometry.n == 4
    assert doc.weld is not None and doc.weld.index.tolist() == [0, 1, 2, 1, 3, 2]
    smoothed = doc.geometry.points + np.array([0.25, 0.5, 0.125])
    data = write_geometry(doc, fmt, smoothed)
    back = read_geometry(data, fmt, weld=False)  # the file as written (the default welds it)
    assert back.geometry.n == 6
    assert np.array_equal(back.geometry.points, smoothed[doc.weld.index])
    if "mesh" not in FORMATS[fmt].kinds:  # XYZ, PCD: the vertices, without the faces
        assert back.geometry.faces is None
        return
    assert back.geometry.faces.tolist() == [[0, 1, 2], [3, 4, 5]]


def test_comments_survive_ply_and_obj() -> None:
    text = b"# CC BY 4.0 attribution: someone\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
    doc = read_geometry(text, "obj")
    assert doc.comments == ["CC BY 4.0 attribution: someone"]
    for fmt in ("ply", "obj", "json"):
        back = read_geometry(write_geometry(doc, fmt), fmt)
        assert "CC BY 4.0 attribution: someone" in back.comments


def test_with_points_keeps_connectivity() -> None:
    doc = _mesh_doc()
    moved = doc.with_points(doc.geometry.points + 1.0)
    assert np.array_equal(moved.geometry.faces, doc.geometry.faces)
    assert moved.polylines is doc.polylines
    assert np.array_equal(moved.geometry.points, doc.geometry.points + 1.0)


def test_comment_line_breaks_cannot_break_headers() -> None:
    doc = read_geometry(
        b'{"points": [[0, 0, 0], [1, 0, 0], [0, 1, 0]], "faces": [[0, 1, 2]],'
        b' "comments": ["two\\nlines\\r\\nelement vertex 9"]}',
        "json",
    )
    for fmt in ("ply", "obj"):
        back = read_geometry(write_geometry(doc, fmt), fmt)
        assert back.geometry.n == 3 and back.geometry.faces.tolist() == [[0, 1, 2]]
        assert back.comments[0] == "two lines  element vertex 9"


def test_two_vertex_loop_is_an_open_polyline() -> None:
    doc = read_geometry(b"v 0 0 0\nv 1 0 0\nl 1 2 1\n", "obj")
    assert [(p.indices.tolist(), p.closed) for p in doc.polylines] == [([0, 1], False)]
    assert doc.geometry.edges.tolist() == [[0, 1]]


@pytest.mark.parametrize("fmt", ["ply", "obj"])
def test_repeated_round_trips_do_not_pile_up_comments(fmt: str) -> None:
    doc = read_geometry(b"# source: somewhere\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "obj")
    once = read_geometry(write_geometry(doc, fmt), fmt)
    twice = read_geometry(write_geometry(once, fmt), fmt)
    assert once.comments == twice.comments == ["source: somewhere", "written by geosmooth"]
