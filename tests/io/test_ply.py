"""PLY reader details: encodings, polygons, edges, extra properties, unknown elements."""

from __future__ import annotations

import time

import numpy as np
import pytest

from service.io import read_geometry
from tests.io.io_builders import ply_bytes

ENCODINGS = ["ascii", "binary_little_endian", "binary_big_endian"]
XYZ3 = [("float", "x"), ("float", "y"), ("float", "z")]
SQUARE = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0.5, 0]], dtype=float)


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_polygons_are_fan_triangulated(encoding: str) -> None:
    data = ply_bytes(encoding, XYZ3, SQUARE, [[0, 1, 2, 3], [1, 4, 2]])
    g = read_geometry(data, "ply").geometry
    assert g.faces.tolist() == [[0, 1, 2], [0, 2, 3], [1, 4, 2]]


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_all_encodings_read_the_same_values(encoding: str) -> None:
    pts = np.random.default_rng(1).standard_normal((50, 3))
    props = [("double", "x"), ("double", "y"), ("double", "z")]
    g = read_geometry(ply_bytes(encoding, props, pts, [[0, 1, 2]]), "ply").geometry
    assert np.array_equal(g.points, pts)


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_float_properties_read_as_float32_values(encoding: str) -> None:
    pts = np.array([[0.1, 0.2, 0.3], [1, 2, 3], [4, 5, 6]])
    g = read_geometry(ply_bytes(encoding, XYZ3, pts), "ply").geometry
    assert g.points.dtype == np.float64
    assert np.array_equal(g.points, pts.astype(np.float32).astype(np.float64))


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_extra_vertex_properties_are_ignored(encoding: str) -> None:
    props = [
        ("float32", "x"),
        ("uchar", "red"),
        ("float32", "y"),
        ("float", "confidence"),
        ("float32", "z"),
        ("int32", "intensity"),
        ("float", "nx"),
        ("uint8", "green"),
    ]
    rows = np.array([[1.5, 200, 2.5, 0.5, 3.5, -7, 0.25, 9], [4, 1, 5, 1, 6, 2, 3, 4]], dtype=float)
    g = read_geometry(ply_bytes(encoding, props, rows), "ply").geometry
    assert g.points.tolist() == [[1.5, 2.5, 3.5], [4.0, 5.0, 6.0]]


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_face_list_named_vertex_index_with_uint(encoding: str) -> None:
    data = ply_bytes(
        encoding, XYZ3, SQUARE, [[0, 1, 2]], face_types=("uchar", "uint"), face_name="vertex_index"
    )
    assert read_geometry(data, "ply").geometry.faces.tolist() == [[0, 1, 2]]


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_unknown_list_element_is_skipped(encoding: str) -> None:
    # like bun000.ply's range_grid: lists of 0 or 1 index, varying length
    grid = [[], [3], [], [], [1], [0], []] * 50
    data = ply_bytes(
        encoding,
        XYZ3,
        SQUARE,
        [[0, 1, 2]],
        extra_elements=[("range_grid", "list uchar int vertex_indices", grid)],
    )
    doc = read_geometry(data, "ply")
    assert doc.geometry.faces.tolist() == [[0, 1, 2]]
    assert doc.notes == ["kept PLY element 'range_grid' (350 entries) as it is"]


def test_unknown_element_with_scalars_and_lists_before_faces() -> None:
    text = (
        b"ply\nformat ascii 1.0\ncomment made by hand\nobj_info scanner 1\nelement vertex 3\n"
        b"property float x\nproperty float y\nproperty float z\n"
        b"element material 2\nproperty uchar r\nproperty list uchar float coeffs\n"
        b"element face 1\nproperty list uchar int vertex_indices\nend_header\n"
        b"0 0 0\n1 0 0\n0 1 0\n1 2 0.5 0.25\n3 0\n3 0 1 2\n"
    )
    doc = read_geometry(text, "ply")
    assert doc.geometry.faces.tolist() == [[0, 1, 2]]
    assert doc.comments == ["made by hand"]
    assert doc.notes == ["kept PLY element 'material' (2 entries) as it is"]


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_mixed_polygon_sizes_take_the_general_path(encoding: str) -> None:
    faces = [[0, 1, 2], [0, 2, 3, 4], [1, 2, 3], [0, 1, 2, 3, 4]]
    data = ply_bytes(encoding, XYZ3, SQUARE, faces)
    g = read_geometry(data, "ply").geometry
    assert g.faces.tolist() == [
        [0, 1, 2],
        [0, 2, 3],
        [0, 3, 4],
        [1, 2, 3],
        [0, 1, 2],
        [0, 2, 3],
        [0, 3, 4],
    ]


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_degenerate_faces_are_dropped_and_noted(encoding: str) -> None:
    faces = [[0, 1, 2], [3, 3, 1], [0, 1], [0, 1, 1, 2]]
    doc = read_geometry(ply_bytes(encoding, XYZ3, SQUARE, faces), "ply")
    # the quad 0 1 1 2 fans into (0 1 1) dropped and (0 1 2) kept
    assert doc.geometry.faces.tolist() == [[0, 1, 2], [0, 1, 2]]
    assert "dropped 1 face with fewer than 3 vertices" in doc.notes
    assert "dropped 2 triangles that repeat a vertex" in doc.notes


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_2d_vertices(encoding: str) -> None:
    props = [("float", "x"), ("float", "y")]
    g = read_geometry(ply_bytes(encoding, props, SQUARE[:, :2], [[0, 1, 2]]), "ply").geometry
    assert g.dim == 2
    assert g.points.tolist() == SQUARE[:, :2].tolist()


def test_edge_element_ascii() -> None:
    text = (
        b"ply\nformat ascii 1.0\nelement vertex 3\nproperty double x\nproperty double y\n"
        b"property double z\nelement edge 3\nproperty int vertex1\nproperty int vertex2\n"
        b"property uchar red\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 5\n1 2 5\n2 2 9\n"
    )
    doc = read_geometry(text, "ply")
    assert doc.geometry.edges.tolist() == [[0, 1], [1, 2]]
    assert doc.standalone_edges.tolist() == [[0, 1], [1, 2]]
    assert "dropped 1 edge that repeat a vertex" in doc.notes


def test_edge_index_out_of_range() -> None:
    text = (
        b"ply\nformat ascii 1.0\nelement vertex 2\nproperty double x\nproperty double y\n"
        b"element edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n0 0\n1 0\n0 5\n"
    )
    from service.io import FormatError

    with pytest.raises(FormatError, match="edge 0 refers to vertex 5 but the file has 2 vertices"):
        read_geometry(text, "ply")


def test_crlf_header_and_body() -> None:
    data = ply_bytes("ascii", XYZ3, SQUARE, [[0, 1, 2]]).replace(b"\n", b"\r\n")
    g = read_geometry(data, "ply").geometry
    assert g.n == 5 and g.faces.tolist() == [[0, 1, 2]]


def test_large_skipped_ascii_element_is_fast() -> None:
    grid = [[i] if i % 3 else [] for i in range(200_000)]
    data = ply_bytes(
        "ascii",
        XYZ3,
        SQUARE,
        extra_elements=[("range_grid", "list uchar int vertex_indices", grid)],
    )
    start = time.process_time()  # CPU time: what the reader costs, whatever the load
    doc = read_geometry(data, "ply")
    assert time.process_time() - start < 1.0
    assert doc.geometry.n == 5


def test_large_variable_binary_list_element() -> None:
    grid = [[i % 5] if i % 3 else [] for i in range(100_000)]
    faces = [[0, 1, 2, 3]] * 10 + [[1, 4, 2]]
    data = ply_bytes(
        "binary_big_endian",
        XYZ3,
        SQUARE,
        faces,
        extra_elements=[("range_grid", "list uchar int vertex_indices", grid)],
    )
    start = time.process_time()  # CPU time: what the reader costs, whatever the load
    doc = read_geometry(data, "ply")
    assert time.process_time() - start < 1.0
    assert len(doc.geometry.faces) == 21
