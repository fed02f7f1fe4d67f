"""Malformed files give one FormatError with a useful message, never a raw numpy error."""

from __future__ import annotations

import numpy as np
import pytest

from service.io import FORMATS, FormatError, read_geometry
from tests.io.io_builders import ply_bytes

XYZ3 = [("float", "x"), ("float", "y"), ("float", "z")]
TRI = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], dtype=float)
FACES = [[0, 1, 2], [1, 3, 2]]


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("data", [b"", b"\n\n  \n"])
def test_empty_file(fmt: str, data: bytes) -> None:
    with pytest.raises(FormatError, match=r"empty|no points") as info:
        read_geometry(data, fmt)
    assert info.value.fmt == fmt


@pytest.mark.parametrize("encoding", ["binary_little_endian", "binary_big_endian"])
@pytest.mark.parametrize("cut", [1, 10, 30])
def test_truncated_binary_ply(encoding: str, cut: int) -> None:
    data = ply_bytes(encoding, XYZ3, TRI, FACES)
    with pytest.raises(FormatError, match="truncated"):
        read_geometry(data[:-cut], "ply")


def test_truncated_binary_ply_in_vertices() -> None:
    data = ply_bytes("binary_little_endian", XYZ3, TRI, FACES)
    header_end = data.index(b"end_header\n") + len(b"end_header\n")
    with pytest.raises(FormatError, match=r"truncated: element 'vertex' \(4 entries\)"):
        read_geometry(data[: header_end + 20], "ply")


def test_binary_ply_with_more_data_than_declared() -> None:
    data = ply_bytes("binary_little_endian", XYZ3, TRI, FACES)
    with pytest.raises(FormatError, match="bytes after the last element"):
        read_geometry(data + b"\x01\x02\x03\x04\x05", "ply")


def test_ascii_ply_with_fewer_lines_than_declared() -> None:
    data = ply_bytes("ascii", XYZ3, TRI, FACES)
    data = data.replace(b"element face 2", b"element face 3")
    with pytest.raises(FormatError, match="declares 3 face entries but the file ends after 2"):
        read_geometry(data, "ply")


def test_ascii_ply_with_more_lines_than_declared() -> None:
    data = ply_bytes("ascii", XYZ3, TRI, FACES) + b"3 0 1 3\n"
    with pytest.raises(FormatError, match=r"line 16: 1 more lines than the header declares"):
        read_geometry(data, "ply")


def test_ascii_ply_wrong_vertex_count_is_caught() -> None:
    data = ply_bytes("ascii", XYZ3, TRI, FACES)
    # one vertex too few declared: the 4th vertex line is read as a face
    with pytest.raises(FormatError, match=r"^line 13: too many values for a face entry$"):
        read_geometry(data.replace(b"element vertex 4", b"element vertex 3"), "ply")
    # one too many: the first face line is read as a vertex
    with pytest.raises(FormatError, match=r"^line 14: expected 3 values for a vertex entry"):
        read_geometry(data.replace(b"element vertex 4", b"element vertex 5"), "ply")


def test_ascii_ply_non_numeric_token_names_the_line() -> None:
    data = ply_bytes("ascii", XYZ3, TRI, FACES).replace(b"1.0 1.0 0.0", b"1.0 oops 0.0")
    with pytest.raises(FormatError, match=r"line 13: 'oops' is not a number") as info:
        read_geometry(data, "ply")
    assert info.value.line == 13


def test_ascii_ply_wrong_value_count_names_the_line() -> None:
    data = ply_bytes("ascii", XYZ3, TRI, FACES).replace(b"1.0 1.0 0.0", b"1.0 1.0")
    with pytest.raises(
        FormatError, match=r"line 13: expected 3 values for a vertex entry, found 2"
    ):
        read_geometry(data, "ply")


@pytest.mark.parametrize("encoding", ["ascii", "binary_little_endian", "binary_big_endian"])
def test_ply_face_index_out_of_range(encoding: str) -> None:
    data = ply_bytes(encoding, XYZ3, TRI, [[0, 1, 2], [1, 900, 2]])
    with pytest.raises(
        FormatError, match="face 1 refers to vertex 900 but the file has 4 vertices"
    ):
        read_geometry(data, "ply")


@pytest.mark.parametrize(
    ("header", "message"),
    [
        (b"garbage\x00\xff\nend_header\n", "does not start with 'ply'"),
        (b"ply\nformat ascii 1.0\nelement vertex 3\n", "no 'end_header'"),
        (
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n0\n",
            "no 'x' and 'y'",
        ),
        (b"ply\nformat ascii 1.0\nelement vertex x\nend_header\n", "line 3: bad element line"),
        (b"ply\nformat ebcdic 1.0\nend_header\n", "line 2: bad format line"),
        (
            b"ply\nformat ascii 1.0\nproperty float x\nend_header\n",
            "line 3: property declared before",
        ),
        (
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nend_header\n",
            "line 4: unknown property type 'float128'",
        ),
        (b"ply\nformat ascii 1.0\nwhatever 3\nend_header\n", "line 3: unknown keyword 'whatever'"),
        (b"ply\nelement vertex 0\nend_header\n", "no 'format' line"),
        (
            b"ply\nformat ascii 1.0\nelement face 0\n"
            b"property list uchar int vertex_indices\nend_header\n",
            "no 'vertex' element",
        ),
        (
            b"ply\nformat ascii 1.0\nelement vertex 0\n"
            b"property float x\nproperty float y\nend_header\n",
            "no points",
        ),
    ],
)
def test_bad_ply_header(header: bytes, message: str) -> None:
    with pytest.raises(FormatError, match=message):
        read_geometry(header, "ply")


def test_obj_non_numeric_token() -> None:
    data = b"# a comment\nv 0 0 0\nv 1 0 zero\nv 0 1 0\nf 1 2 3\n"
    with pytest.raises(FormatError, match=r"^line 3: 'zero' is not a number$") as info:
        read_geometry(data, "obj")
    assert info.value.line == 3 and info.value.fmt == "obj"


def test_obj_bad_face_token() -> None:
    data = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x/3\n"
    with pytest.raises(FormatError, match=r"line 4: 'x' is not a vertex index"):
        read_geometry(data, "obj")


def test_obj_face_index_out_of_range() -> None:
    data = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 900\n"
    with pytest.raises(
        FormatError, match=r"line 5: face refers to vertex 900 but the file has 3 vertices"
    ):
        read_geometry(data, "obj")


def test_obj_relative_index_out_of_range() -> None:
    data = b"v 0 0 0\nv 1 0 0\nf -1 -2 -3\nv 0 1 0\n"
    with pytest.raises(FormatError, match=r"line 3: face refers to relative vertex -3 but only 2"):
        read_geometry(data, "obj")


def test_obj_index_zero() -> None:
    with pytest.raises(FormatError, match="index 0 is not valid"):
        read_geometry(b"v 0 0 0\nv 1 0 0\nl 0 1\n", "obj")


def test_obj_polyline_index_out_of_range() -> None:
    with pytest.raises(FormatError, match="line 3: polyline refers to vertex 7"):
        read_geometry(b"v 0 0 0\nv 1 0 0\nl 1 2 7\n", "obj")


def test_obj_short_vertex() -> None:
    with pytest.raises(FormatError, match="line 2: a vertex needs 3 coordinates, found 2"):
        read_geometry(b"v 0 0 0\nv 1 0\n", "obj")


def test_obj_without_vertices() -> None:
    with pytest.raises(FormatError, match="no 'v' lines"):
        read_geometry(b"hello world\nthis is not obj\n", "obj")


def test_xyz_non_numeric_token() -> None:
    with pytest.raises(
        FormatError, match=r"line 3: '2,5' is not a number|line 3: 'x' is not a number"
    ):
        read_geometry(b"1 2 3\n4 5 6\n7 x 9\n", "xyz")


def test_xyz_ragged_rows() -> None:
    with pytest.raises(FormatError, match="line 2: expected 3 values for a point, found 4"):
        read_geometry(b"1 2 3\n4 5 6 7\n", "xyz")


def test_xyz_single_column() -> None:
    with pytest.raises(FormatError, match="at least 2 columns"):
        read_geometry(b"1\n2\n3\n", "xyz")


def test_xyz_dims_too_large() -> None:
    with pytest.raises(FormatError, match="xyz_dims=4 but the file has 3 columns"):
        read_geometry(b"1 2 3\n", "xyz", xyz_dims=4)


def test_json_syntax_error_names_line() -> None:
    with pytest.raises(FormatError, match=r"line 2 column \d+: invalid JSON") as info:
        read_geometry(b'{"points": [[0, 0]],\n "faces": [[0, 1, 2]]]\n}', "json")
    assert info.value.line == 2


@pytest.mark.parametrize(
    ("obj", "message"),
    [
        (b"[[0, 0, 0]]", "top level must be an object"),
        (b'{"point": [[0, 0]]}', "no 'points' key"),
        (b'{"points": [[0, 0]], "face": []}', "unknown key 'face'"),
        (b'{"points": [[0, 0], [1]]}', "'points' must be"),
        (b'{"points": [["a", "b"]]}', "'points' must be"),
        (b'{"points": []}', "'points' must be a non-empty"),
        (
            b'{"points": [[0, 0], [1, 0], [0, 1]], "faces": [[0, 1, 5]]}',
            "face 0 refers to vertex 5 but the file has 3 vertices",
        ),
        (b'{"points": [[0, 0], [1, 0]], "edges": [[0, 1, 1]]}', "'edges' must be"),
        (b'{"points": [[0, 0], [1, 0]], "polylines": [[0, 1]]}', "polyline 0 must be an object"),
        (
            b'{"points": [[0, 0], [1, 0]], "polylines": [{"indices": [0, 3]}]}',
            "polyline 0 refers to vertex 3",
        ),
        (
            b'{"points": [[0, 0], [1, 0]], "faces": [[0, 1.5, 1]]}',
            "indices must be integers, found 1.5",
        ),
    ],
)
def test_json_schema_errors(obj: bytes, message: str) -> None:
    with pytest.raises(FormatError, match=message):
        read_geometry(obj, "json")


def test_geojson_in_a_json_file_is_read_as_geojson() -> None:
    data = b'{"type": "FeatureCollection", "features": []}'
    with pytest.raises(FormatError, match="GeoJSON has no LineString"):
        read_geometry(data, filename="coast.json")
    line = b'{"type": "LineString", "coordinates": [[4.7, 50.9], [4.71, 50.91]]}'
    assert read_geometry(line, filename="track.json").source_format == "geojson"


def test_errors_are_one_line_and_serialisable() -> None:
    with pytest.raises(FormatError) as info:
        read_geometry(b"v 0 0 0\nv 1 0 zero\n", "obj")
    err = info.value
    assert "\n" not in str(err)
    assert err.to_dict() == {
        "code": "format-error",
        "message": "line 2: 'zero' is not a number",
        "field": "file",
        "format": "obj",
        "line": 2,
    }
    assert isinstance(err, ValueError)


def test_non_finite_coordinates_are_a_geometry_error() -> None:
    from service.core.errors import NonFiniteCoordinates

    with pytest.raises(NonFiniteCoordinates):
        read_geometry(b"1 2 3\nnan 0 0\n", "xyz")


def test_line_numbers_count_blank_lines() -> None:
    data = ply_bytes("ascii", XYZ3, TRI, FACES).replace(b"1.0 0.0 0.0\n", b"1.0 0.0 0.0\n\n  \n")
    g = read_geometry(data, "ply").geometry
    assert g.n == 4 and g.faces.tolist() == FACES
    bad = data.replace(b"1.0 1.0 0.0", b"1.0 1.0 oops")
    with pytest.raises(FormatError, match=r"^line 15: 'oops' is not a number$"):
        read_geometry(bad, "ply")
    with pytest.raises(FormatError, match=r"^line 4: 'oops' is not a number$"):
        read_geometry(b"1 2 3\n\n\n1 oops 3\n", "xyz")
    with pytest.raises(FormatError, match=r"^line 4: 'oops' is not a number$"):
        read_geometry(b"# c\n1 2 3\n\n1 oops 3\n", "xyz")


@pytest.mark.parametrize(
    ("count", "message"),
    [(2**31 - 1, "truncated"), (-5, "negative list length -5"), (1000, "truncated")],
)
def test_binary_ply_absurd_list_lengths(count: int, message: str) -> None:
    data = ply_bytes("binary_little_endian", XYZ3, TRI, FACES, face_types=("int", "int"))
    at = data.index(b"end_header\n") + len(b"end_header\n") + 4 * 12
    data = data[:at] + np.array([count], "<i4").tobytes() + data[at + 4 :]
    with pytest.raises(FormatError, match=message):
        read_geometry(data, "ply")


def test_deeply_nested_json_is_a_format_error() -> None:
    from service.io import FormatError, read_geometry

    with pytest.raises(FormatError, match="nested too deeply"):
        read_geometry(b"[" * 100_000 + b"]" * 100_000, "json")


# issue 15 item 7: rows with the wrong number of columns are never shifted into the next one


def test_xyz_rows_that_only_add_up_are_refused() -> None:
    # 3 + 2 + 4 values = 3 rows of 3: the old reader took them as 3 shifted points
    with pytest.raises(FormatError, match=r"^line 2: expected 3 values for a point, found 2$"):
        read_geometry(b"1 2 3\n4 5\n6 7 8 9\n", "xyz")


def test_ascii_ply_rows_that_only_add_up_are_refused() -> None:
    data = ply_bytes("ascii", XYZ3, TRI, FACES)
    data = data.replace(b"1.0 0.0 0.0\n0.0 1.0 0.0", b"1.0 0.0\n0.0 0.0 1.0 0.0")
    # header of 9 lines, vertex 0 on line 10: vertex 1 (line 11) has 2 values, vertex 2 has 4
    with pytest.raises(FormatError, match=r"line 11: expected 3 values for a vertex entry"):
        read_geometry(data, "ply")


@pytest.mark.parametrize(
    "body",
    [
        b'{"points": [[true, 0, 0], [1, 0, 0]]}',
        b'{"points": [[0, 0, 0], [1, 0, 0]], "weights": [true, 1]}',
        b'{"points": [[0, 0, 0], [1, 0, 0]], "edges": [[false, true]]}',
        b'{"points": [[0, 0], [1, 0]], "attributes": {"a": [true, false]}}',
    ],
)
def test_json_booleans_are_not_numbers(body: bytes) -> None:
    with pytest.raises(FormatError, match="not booleans"):
        read_geometry(body, "json")
