"""OBJ and XYZ reader details."""

from __future__ import annotations

import numpy as np
import pytest

from service.io import read_geometry


def test_obj_all_face_index_forms() -> None:
    text = (
        b"mtllib x.mtl\no thing\ng group\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
        b"vt 0 0\nvt 1 0\nvn 0 0 1\ns off\nusemtl red\n"
        b"f 1 2 3\nf 1/1 3/2 4/1\nf 1//1 2//1 4//1\nf 2/1/1 3/2/1 4/2/1\n"
    )
    g = read_geometry(text, "obj").geometry
    assert g.faces.tolist() == [[0, 1, 2], [0, 2, 3], [0, 1, 3], [1, 2, 3]]


def test_obj_negative_indices_are_relative() -> None:
    text = b"v 0 0 0\nv 1 0 0\nv 1 1 0\nf -3 -2 -1\nv 0 1 0\nf -4/1 -2/2 -1//3\nl -1 -2\n"
    doc = read_geometry(text, "obj")
    assert doc.geometry.faces.tolist() == [[0, 1, 2], [0, 2, 3]]
    assert doc.polylines[0].indices.tolist() == [3, 2]


def test_obj_polygons_fan_triangulated() -> None:
    text = b"v 0 0 0\nv 1 0 0\nv 2 1 0\nv 1 2 0\nv 0 1 0\nf 1 2 3 4 5\n"
    assert read_geometry(text, "obj").geometry.faces.tolist() == [[0, 1, 2], [0, 2, 3], [0, 3, 4]]


def test_obj_extra_vertex_columns_ignored() -> None:
    text = b"v 1 2 3 1.0\nv 4 5 6 0.1 0.2 0.3\nv 7 8 9\n"
    g = read_geometry(text, "obj").geometry
    assert g.points.tolist() == [[1, 2, 3], [4, 5, 6], [7, 8, 9]]


def test_obj_polylines_open_closed_and_edges() -> None:
    text = b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nl 1 2 3 4 1\nl 3 1\n"
    doc = read_geometry(text, "obj")
    assert [(p.indices.tolist(), p.closed) for p in doc.polylines] == [
        ([0, 1, 2, 3], True),
        ([2, 0], False),
    ]
    assert doc.geometry.edges.tolist() == [[0, 1], [1, 2], [2, 3], [3, 0], [2, 0]]
    assert doc.geometry.kind == "curve"


def test_obj_polyline_repeats_are_collapsed() -> None:
    text = b"v 0 0 0\nv 1 0 0\nv 1 1 0\nl 1 2 2 3\nl 2 2\n"
    doc = read_geometry(text, "obj")
    assert [p.indices.tolist() for p in doc.polylines] == [[0, 1, 2]]
    assert "dropped 1 polyline with fewer than 2 distinct vertices" in doc.notes


def test_obj_degenerate_faces_dropped() -> None:
    text = b"v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\nf 3 3 2\n"
    doc = read_geometry(text, "obj")
    assert doc.geometry.faces.tolist() == [[0, 1, 2]]
    assert doc.notes == ["dropped 1 triangle that repeat a vertex"]


def test_obj_unknown_statements_noted() -> None:
    doc = read_geometry(b"v 0 0 0\nv 1 0 0\np 1\np 2\ncurv 0 1 1 2\n", "obj")
    assert doc.notes == ["ignored 1 OBJ 'curv' statements", "ignored 2 OBJ 'p' statements"]


def test_obj_leading_whitespace_and_crlf() -> None:
    text = b"  v 0 0 0\r\n\tv 1 0 0\r\nv 0 1 0\r\n f 1 2 3\r\n"
    g = read_geometry(text, "obj").geometry
    assert g.n == 3 and g.faces.tolist() == [[0, 1, 2]]


@pytest.mark.parametrize("sep", [b" ", b"\t", b",", b", ", b"  "])
def test_xyz_separators(sep: bytes) -> None:
    text = sep.join([b"1.5", b"2", b"-3e2"]) + b"\n" + sep.join([b"4", b"5", b"6"]) + b"\n"
    g = read_geometry(text, "xyz").geometry
    assert g.points.tolist() == [[1.5, 2.0, -300.0], [4.0, 5.0, 6.0]]


def test_xyz_two_columns_are_2d() -> None:
    g = read_geometry(b"1 2\n3 4\n5 6\n", "xyz").geometry
    assert g.dim == 2 and g.kind == "cloud"


def test_xyz_extra_columns_ignored_and_noted() -> None:
    doc = read_geometry(b"1 2 3 255 0 0\n4 5 6 0 255 0\n", "xyz")
    assert doc.geometry.points.tolist() == [[1, 2, 3], [4, 5, 6]]
    assert doc.notes == ["kept 3 extra columns per line: red, green, blue"]
    assert doc.attributes["green"].tolist() == [0, 255]


def test_xyz_dims_override() -> None:
    doc = read_geometry(b"1 2 3 4 5\n6 7 8 9 10\n", "xyz", xyz_dims=5)
    assert doc.geometry.dim == 5 and doc.notes == []


def test_xyz_header_and_comments() -> None:
    doc = read_geometry(b"# scan 3\n\nx,y,z\n1,2,3\n# middle comment\n4,5,6\n", "xyz")
    assert doc.geometry.points.tolist() == [[1, 2, 3], [4, 5, 6]]
    assert doc.comments == ["scan 3"]
    assert doc.notes == ["read header line 3: 'x,y,z'"]


def test_xyz_weld() -> None:
    doc = read_geometry(b"1 2 3\n4 5 6\n1 2 3\n", "xyz", weld=True)
    assert doc.geometry.n == 2
    assert doc.weld.index.tolist() == [0, 1, 0]


def test_xyz_full_precision_text() -> None:
    g = read_geometry(b"0.1 0.2 0.30000000000000004\n", "xyz").geometry
    assert g.points.tolist() == [[0.1, 0.2, 0.30000000000000004]]
    assert np.float64(0.1) + np.float64(0.2) == g.points[0, 2]
