"""Write the fuzz corpus: small malformed files of every format and what reading them must give.

Run ``python tests/corpus/make_corpus.py`` to regenerate ``tests/corpus/files/`` and
``tests/corpus/manifest.json`` (both committed). Each manifest entry names a file, its format
(the file's extension), the expected error ``code`` (``format-error``, ``unsupported-format``,
or a geometry error code such as ``non-finite-coordinates``) and a regular expression the
one-line message must match. The io tests read every file; the API and CLI tests send the same
files through their channels and expect the same codes (HTTP 400/415/422, CLI exit 3 or 4).
"""

from __future__ import annotations

import io
import json
import struct
from collections.abc import Callable
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
FILES = HERE / "files"

Case = tuple[str, bytes, str, str]  # file name, content, code, message pattern


def _ply(body: bytes, header: str = "", fmt: str = "ascii") -> bytes:
    head = (
        f"ply\nformat {fmt} 1.0\n{header}element vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
    )
    return head.encode() + body


def _ply_cases() -> list[Case]:
    tri = b"0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
    le = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], "<f4").tobytes()
    return [
        ("ply_no_end_header.ply", b"ply\nformat ascii 1.0\nelement vertex 1\n", "format-error",
         "end_header"),
        ("ply_bad_keyword.ply", _ply(tri, "colour red\n"), "format-error", "unknown keyword"),
        ("ply_bad_type.ply", tri.join([b"ply\nformat ascii 1.0\nelement vertex 3\n"
                                       b"property flaot x\nend_header\n", b""]),
         "format-error", "unknown property type"),
        ("ply_short_row_shifted.ply", _ply(b"0 0 0\n1 0\n0 0 1 0\n3 0 1 2\n"), "format-error",
         "line 11: expected 3 values"),
        ("ply_too_many_rows.ply", _ply(tri + b"0 0 0\n"), "format-error", "more lines"),
        ("ply_too_few_rows.ply", _ply(b"0 0 0\n1 0 0\n"), "format-error", "entries"),
        ("ply_not_a_number.ply", _ply(b"0 0 0\n1 x 0\n0 1 0\n3 0 1 2\n"), "format-error",
         "'x' is not a number"),
        ("ply_index_out_of_range.ply", _ply(b"0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n"), "format-error",
         "refers to vertex 7"),
        ("ply_fractional_index.ply", _ply(b"0 0 0\n1 0 0\n0 1 0\n3 0 1 1.5\n"), "format-error",
         "declared int32 but holds 1.5"),
        ("ply_nan.ply", _ply(b"0 0 0\n1 nan 0\n0 1 0\n3 0 1 2\n"), "non-finite-coordinates",
         "finite"),
        ("ply_truncated_binary.ply", _ply(le[:20], fmt="binary_little_endian"), "format-error",
         "truncated"),
        ("ply_huge_count.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex "
         b"999999999999\nproperty float x\nproperty float y\nend_header\n" + le,
         "format-error", "999999999999 entries"),
        ("ply_bad_list_length.ply", _ply(le + b"\xff\x00\x00\x00\x00", fmt="binary_little_endian"),
         "format-error", "truncated"),
        ("ply_no_vertex.ply", b"ply\nformat ascii 1.0\nelement face 0\nproperty list uchar int"
         b" vertex_indices\nend_header\n", "format-error", "no 'vertex' element"),
    ]  # fmt: skip


def _text_cases() -> list[Case]:
    return [
        ("obj_bad_token.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n", "format-error",
         "line 4: 'x' is not a vertex index"),
        ("obj_index_zero.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "format-error",
         "index 0"),
        ("obj_out_of_range.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", "format-error",
         "refers to vertex 9"),
        ("obj_short_vertex.obj", b"v 0 0\n", "format-error", "needs 3 coordinates"),
        ("obj_no_vertices.obj", b"# nothing\ng group\n", "format-error", "no 'v' lines"),
        ("xyz_short_row_shifted.xyz", b"1 2 3\n4 5\n6 7 8 9\n", "format-error",
         "line 2: expected 3 values"),
        ("xyz_bad_token.xyz", b"1 2 3\n4 five 6\n", "format-error", "'five' is not a number"),
        ("xyz_underscore.xyz", b"1 2 3\n4 5 1_000\n", "format-error", "'1_000' is not a number"),
        ("xyz_single_column.xyz", b"1\n2\n", "format-error", "at least 2 columns"),
        ("xyz_inf.xyz", b"1 2 3\n4 inf 6\n", "non-finite-coordinates", "finite"),
        ("json_boolean_coordinate.json", b'{"points": [[true, 0, 0], [1, 0, 0]]}',
         "format-error", "not booleans"),
        ("json_syntax.json", b'{"points": [[0, 0, 0],]}', "format-error", "invalid JSON"),
        ("json_unknown_key.json", b'{"points": [[0, 0]], "face": []}', "format-error",
         "unknown key 'face'"),
        ("json_huge_int.json", b'{"points": [[' + b"9" * 5000 + b", 0]]}", "format-error",
         "invalid JSON|must be"),
        ("json_string_coordinate.json", b'{"points": [["1", 0]]}', "format-error", "numbers"),
        ("off_bad_keyword.off", b"OFFF\n3 1 0\n", "format-error", "not an OFF file"),
        ("off_bad_counts.off", b"OFF\n3 x 0\n", "format-error", "counts line"),
        ("off_short_face.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1\n", "format-error",
         "line 6: a face of 3 vertices"),
        ("off_too_few_vertices.off", b"OFF\n4 0 0\n0 0 0\n1 0 0\n", "format-error",
         "declares 4 vertices"),
        ("stl_ascii_quad.stl", b"solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n"
         b"vertex 1 0 0\nvertex 1 1 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid s\n",
         "format-error", "line 8: a facet has 4 vertices"),
        ("stl_ascii_unterminated.stl", b"solid s\nfacet normal 0 0 1\nouter loop\n",
         "format-error", "ends inside a solid"),
        ("stl_ascii_garbage.stl", b"solid s\nfacet normal 0 0 1\nbanana\n", "format-error",
         "line 3: expected outer"),
        ("pcd_unknown_keyword.pcd", b"VERSION 0.7\nFIELDS x y z\nSIZES 4 4 4\n", "format-error",
         "unknown header keyword"),
        ("pcd_no_data.pcd", b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\n",
         "format-error", "no DATA line"),
        ("pcd_bad_type.pcd", b"FIELDS x y z\nSIZE 4 4 3\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1\n"
         b"HEIGHT 1\nPOINTS 1\nDATA ascii\n0 0 0\n", "format-error", "unsupported TYPE"),
        ("pcd_ascii_short_row.pcd", b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
         b"WIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA ascii\n0 0\n1 1 1 1\n", "format-error",
         "expected 3 values"),
        ("gpx_not_xml.gpx", b"<gpx><trk><trkseg><trkpt lat='1' lon='2'>", "format-error", "GPX"),
        ("gpx_no_tracks.gpx", b'<?xml version="1.0"?><gpx version="1.1" creator="x">'
         b'<wpt lat="1" lon="2"/></gpx>', "format-error", "no track segment"),
        ("geojson_no_lines.geojson", b'{"type": "FeatureCollection", "features": []}',
         "format-error", "no LineString"),
        ("geojson_string_coordinate.geojson", b'{"type": "LineString", "coordinates": '
         b'[[1, "2"], [3, 4]]}', "format-error", "must be a number"),
        ("geojson_boolean_coordinate.geojson", b'{"type": "LineString", "coordinates": '
         b"[[1, true], [3, 4]]}", "format-error", "must be a number"),
        ("dxf_garbage.dxf", b"  0\nSECTION\n  2\nENTITIES\n  0\nLINE\n 10\nnot-a-number\n",
         "format-error", "DXF"),
        ("dxf_no_lines.dxf", _dxf_text_only(), "format-error", "no lines, arcs or polylines"),
        ("unknown_extension.svg", b"<svg></svg>", "unsupported-format", "unsupported file ext"),
    ]  # fmt: skip


def _dxf_text_only() -> bytes:
    import ezdxf

    doc = ezdxf.new("R2010")
    doc.modelspace().add_text("only text")
    out = io.StringIO()
    doc.write(out)
    return out.getvalue().encode()


def _binary_cases() -> list[Case]:
    stl = b"\0" * 80 + struct.pack("<I", 2) + b"\0" * 50
    glb = b"glTF" + struct.pack("<II", 2, 20) + b"\0" * 8
    return [
        ("stl_binary_truncated.stl", stl, "format-error", "declares 2 triangles"),
        ("stl_binary_short.stl", b"\0" * 40, "format-error", "shorter than its 84-byte header"),
        ("glb_bad_chunks.glb", glb, "format-error", "GLB"),
        ("glb_no_magic.glb", b"glTX" + b"\0" * 16, "format-error", "no 'glTF' magic"),
        ("las_short.las", b"LASF" + b"\0" * 100, "format-error", "too short for a LAS header"),
        ("las_bad_header.las", b"LASF" + b"\xff" * 400, "format-error", "LAS"),
        ("laz_truncated.laz", _laz()[:600], "format-error", "LAZ"),
        ("pcd_binary_truncated.pcd", b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
         b"WIDTH 10\nHEIGHT 1\nPOINTS 10\nDATA binary\n" + b"\0" * 30, "format-error",
         "truncated"),
        ("pcd_compressed_corrupt.pcd", b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
         b"WIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA binary_compressed\n" + struct.pack("<II", 8, 24)
         + b"\xff" * 8, "format-error", "decompress|LZF"),
        ("e57_garbage.e57", b"ASTM-E57" + b"\0" * 1000, "format-error", "E57"),
    ]  # fmt: skip


def _laz() -> bytes:
    import laspy

    header = laspy.LasHeader(point_format=3, version="1.2")
    las = laspy.LasData(header)
    rng = np.random.default_rng(0)
    las.x, las.y, las.z = rng.uniform(0, 10, (3, 500))
    out = io.BytesIO()
    las.write(out, do_compress=True)
    return out.getvalue()


CASES: list[Callable[[], list[Case]]] = [_ply_cases, _text_cases, _binary_cases]


def main() -> None:
    """Write the files and the manifest."""
    FILES.mkdir(exist_ok=True)
    for old in FILES.iterdir():
        old.unlink()
    manifest = []
    for make in CASES:
        for name, data, code, pattern in make():
            (FILES / name).write_bytes(data)
            manifest.append({"file": name, "code": code, "match": pattern})
    (HERE / "manifest.json").write_text(json.dumps(manifest, indent=1) + "\n")
    print(f"{len(manifest)} files in {FILES}")


if __name__ == "__main__":
    main()
