"""geosmooth JSON, welding and format detection."""

from __future__ import annotations

import json

import numpy as np
import pytest

from service.io import (
    GEOMETRY_JSON_SCHEMA,
    FormatError,
    UnsupportedFormat,
    detect_format,
    document_to_json_obj,
    geometry_from_json_obj,
    read_geometry,
    sniff_format,
    write_geometry,
)


def test_json_full_object() -> None:
    obj = {
        "points": [[0, 0], [1, 0], [1, 1], [0, 1], [2, 2]],
        "faces": [[0, 1, 2, 3]],
        "edges": [[3, 4]],
        "polylines": [{"indices": [0, 1, 2, 0]}, {"indices": [2, 4], "closed": False}],
        "weights": [1, 2, 3, 4, 5],
        "fixed": [4],
        "comments": ["hello"],
    }
    doc = geometry_from_json_obj(obj)
    g = doc.geometry
    assert g.dim == 2 and g.points.dtype == np.float64
    assert g.faces.tolist() == [[0, 1, 2], [0, 2, 3]]
    assert doc.standalone_edges.tolist() == [[3, 4]]
    assert [(p.indices.tolist(), p.closed) for p in doc.polylines] == [
        ([0, 1, 2], True),
        ([2, 4], False),
    ]
    assert g.edges.tolist() == [[3, 4], [0, 1], [1, 2], [2, 0], [2, 4]]
    assert g.weights.tolist() == [1, 2, 3, 4, 5]
    assert g.fixed.tolist() == [4]
    out = document_to_json_obj(doc)
    assert out["points"] == [[float(v) for v in p] for p in obj["points"]]
    assert out["faces"] == [[0, 1, 2], [0, 2, 3]]
    assert out["edges"] == [[3, 4]]
    assert out["polylines"] == [
        {"indices": [0, 1, 2], "closed": True},
        {"indices": [2, 4], "closed": False},
    ]
    assert out["weights"] == [1, 2, 3, 4, 5] and out["fixed"] == [4]
    assert out["comments"] == ["hello"]
    assert geometry_from_json_obj(out).geometry.edges.tolist() == g.edges.tolist()


def test_json_output_is_strict_json_for_infinite_weights() -> None:
    doc = geometry_from_json_obj({"points": [[0.0], [1.0], [2.0]], "weights": [1, float("inf"), 2]})
    assert doc.geometry.fixed_mask().tolist() == [False, True, False]
    data = write_geometry(doc, "json")
    obj = json.loads(data)  # no Infinity token
    assert obj["weights"] == [1.0, 1.0, 2.0] and obj["fixed"] == [1]
    assert read_geometry(data, "json").geometry.fixed_mask().tolist() == [False, True, False]


def test_json_document_to_obj_with_points() -> None:
    doc = geometry_from_json_obj({"points": [[0, 0, 0], [1, 1, 1]]})
    out = document_to_json_obj(doc, points=np.array([[0.5, 0, 0], [1, 1, 1.25]]))
    assert out == {"points": [[0.5, 0.0, 0.0], [1.0, 1.0, 1.25]]}


def test_json_schema_constant_matches_reader_keys() -> None:
    assert GEOMETRY_JSON_SCHEMA["required"] == ["points"]
    assert set(GEOMETRY_JSON_SCHEMA["properties"]) == {
        "points",
        "faces",
        "edges",
        "polylines",
        "weights",
        "fixed",
        "comments",
        "attributes",
        "attribute_types",
        "normals",
        "precision",
    }
    json.dumps(GEOMETRY_JSON_SCHEMA)  # serialisable for OpenAPI


def test_json_bad_weights_are_geometry_errors() -> None:
    from service.core.errors import GeometryError

    with pytest.raises(GeometryError):
        geometry_from_json_obj({"points": [[0], [1]], "weights": [1, -1]})
    with pytest.raises(GeometryError):
        geometry_from_json_obj({"points": [[0], [1]], "weights": [1]})


def test_weld_maps_weights_fixed_polylines() -> None:
    obj = {
        "points": [[0, 0], [1, 0], [0, 0], [2, 0], [1, 0]],
        "polylines": [{"indices": [0, 1, 3]}, {"indices": [2, 4]}],
        "edges": [[0, 2]],
        "weights": [1, 2, 3, 4, 6],
        "fixed": [2],
    }
    doc = geometry_from_json_obj(obj, weld=True)
    g = doc.geometry
    assert g.points.tolist() == [[0, 0], [1, 0], [2, 0]]
    assert doc.weld.index.tolist() == [0, 1, 0, 2, 1]
    assert g.weights.tolist() == [2.0, 4.0, 4.0]  # means of merged weights
    assert g.fixed.tolist() == [0]
    assert [p.indices.tolist() for p in doc.polylines] == [[0, 1, 2], [0, 1]]
    assert doc.standalone_edges is None  # [0, 2] collapsed to a point
    assert "dropped 1 edges that became degenerate after welding" in doc.notes
    out = document_to_json_obj(doc)  # original numbering
    assert len(out["points"]) == 5
    assert out["edges"] == [[0, 2]] and out["fixed"] == [2]
    assert out["weights"] == [1, 2, 3, 4, 6]


def test_weld_drops_faces_that_collapse() -> None:
    text = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 0\nf 1 2 3\nf 2 3 4\nf 1 2 4\n"
    doc = read_geometry(text, "obj", weld=True)
    assert doc.geometry.faces.tolist() == [[0, 1, 2], [1, 2, 0]]
    assert "dropped 1 faces that became degenerate after welding" in doc.notes
    out = read_geometry(write_geometry(doc, "obj"), "obj", weld=False)  # as written
    assert out.geometry.faces.tolist() == [[0, 1, 2], [1, 2, 3], [0, 1, 3]]
    assert read_geometry(write_geometry(doc, "obj"), "obj").weld is not None  # default: welds


def test_weld_treats_signed_zeros_alike() -> None:
    doc = read_geometry(b"0 0 0\n-0.0 0 0\n", "xyz", weld=True)
    assert doc.geometry.n == 1


@pytest.mark.parametrize(
    ("name", "fmt"),
    [
        ("a.ply", "ply"),
        ("A.PLY", "ply"),
        ("dir/x.obj", "obj"),
        ("p.xyz", "xyz"),
        ("g.json", "json"),
    ],
)
def test_detect_format(name: str, fmt: str) -> None:
    assert detect_format(name) == fmt


@pytest.mark.parametrize(
    ("name", "fmt"),
    [
        ("track.gpx", "gpx"),
        ("coast.geojson", "geojson"),
        ("wrench.DXF", "dxf"),
        ("part.stl", "stl"),
        ("cloud.LAZ", "laz"),
        ("scan.e57", "e57"),
    ],
)
def test_formats_once_refused_are_detected(name: str, fmt: str) -> None:
    assert detect_format(name) == fmt


@pytest.mark.parametrize(
    ("name", "message"),
    [
        ("notes.md", r"unsupported file extension '\.md'.*PLY \(\.ply\)"),
        ("shape.svg", r"unsupported file extension '\.svg'.*GPX \(\.gpx\)"),
        ("README", "no file extension"),
    ],
)
def test_refused_formats(name: str, message: str) -> None:
    with pytest.raises(UnsupportedFormat, match=message) as info:
        detect_format(name)
    assert isinstance(info.value, FormatError) and info.value.code == "unsupported-format"


@pytest.mark.parametrize("fmt", ["svg", "banana"])
def test_refused_explicit_format(fmt: str) -> None:
    with pytest.raises(UnsupportedFormat):
        read_geometry(b"1 2 3\n", fmt)
    doc = read_geometry(b"1 2 3\n", "xyz")
    with pytest.raises(UnsupportedFormat):
        write_geometry(doc, fmt)


def test_filename_drives_detection_for_bytes() -> None:
    doc = read_geometry(b"v 1 2 3\n", filename="upload.obj")
    assert doc.source_format == "obj"
    with pytest.raises(FormatError, match="GPX"):
        read_geometry(b"<gpx/>", filename="upload.gpx")


@pytest.mark.parametrize(
    ("data", "fmt"),
    [
        (b"ply\nformat ascii 1.0\n", "ply"),
        (b'  {"points": []}', "json"),
        (b"# comment\nv 1 2 3\n", "obj"),
        (b"# comment\n1, 2, 3\n", "xyz"),
        (b"<?xml version='1.0'?><gpx>", "gpx"),
        (b'{"type": "FeatureCollection", "features": []}', "geojson"),
        (b"solid x\nfacet normal 0 0 1\n", "stl"),
        (b"OFF\n3 1 0\n", "off"),
        (b"# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\n", "pcd"),
        (b"glTF\x02\x00\x00\x00", "glb"),
        (b"  0\nSECTION\n  2\nHEADER\n", "dxf"),
        (b"ASTM-E57\x00\x00", "e57"),
        (b"\x00\x01garbage", None),
    ],
)
def test_sniff_format(data: bytes, fmt: str | None) -> None:
    assert sniff_format(data) == fmt


def test_bytes_without_name_or_format() -> None:
    assert read_geometry(b"1 2 3\n4 5 6\n").source_format == "xyz"
    with pytest.raises(UnsupportedFormat, match="cannot tell the format"):
        read_geometry(b"<svg></svg>")


def test_path_source(tmp_path) -> None:  # type: ignore[no-untyped-def]
    path = tmp_path / "cloud.xyz"
    path.write_bytes(b"1 2 3\n4 5 6\n")
    assert read_geometry(path).geometry.n == 2
    assert read_geometry(str(path)).geometry.n == 2


def test_name_without_extension_falls_back_to_content() -> None:
    assert (
        read_geometry(
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n"
            b"property float y\nend_header\n1 2\n",
            filename="blob",
        ).geometry.dim
        == 2
    )
