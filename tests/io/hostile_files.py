"""Hostile files of the streamed formats (LAS/LAZ, binary PLY, XYZ), issue 34 item 4.

Each builder returns ``{name: bytes}``; the files are read through the ordinary readers
(:func:`service.io.read_geometry`) and the streamed ones (:mod:`service.io.stream`), and through
``geosmooth smooth`` with and without ``--tile-points`` (tests/io/test_stream_checks.py,
tests/cli/test_hostile_paths.py). The corpus of ``tests/corpus`` adds its LAS, LAZ, PLY and XYZ
files to these.
"""

from __future__ import annotations

import io
import re
import struct
from pathlib import Path

import numpy as np

CORPUS = Path(__file__).resolve().parents[1] / "corpus" / "files"
STREAMED_SUFFIXES = (".las", ".laz", ".ply", ".xyz")


def _grid(n: int = 400) -> np.ndarray:
    rng = np.random.default_rng(7)
    k = int(np.ceil(np.sqrt(n)))
    u, v = np.meshgrid(np.arange(k), np.arange(k))
    pts = np.c_[u.ravel(), v.ravel(), np.zeros(k * k)][:n].astype(float)
    pts[:, 2] = 0.01 * rng.standard_normal(n)
    return pts


def las_bytes(n: int = 400, *, compress: bool = False, version: str = "1.2") -> bytes:
    """A valid LAS (LAZ) file of ``n`` points."""
    import laspy

    header = laspy.LasHeader(point_format=3 if version == "1.2" else 6, version=version)
    header.scales = np.array([0.001, 0.001, 0.001])
    las = laspy.LasData(header)
    pts = _grid(n)
    las.x, las.y, las.z = pts[:, 0], pts[:, 1], pts[:, 2]
    out = io.BytesIO()
    las.write(out, do_compress=compress)
    return out.getvalue()


def _set_count(data: bytes, count: int) -> bytes:
    buf = bytearray(data)
    struct.pack_into("<I", buf, 107, min(count, 2**32 - 1))
    if buf[25] >= 4:  # LAS 1.4: the 64-bit count too
        struct.pack_into("<Q", buf, 247, count)
    return bytes(buf)


def las_cases() -> dict[str, bytes]:
    """Lying headers, truncated point data, bad scales, an empty file."""
    good = las_bytes()
    offset = struct.unpack_from("<I", good, 96)[0]
    nan_scale = bytearray(good)
    struct.pack_into("<d", nan_scale, 131, float("nan"))
    laz = las_bytes(compress=True)
    contradiction = bytearray(good)
    contradiction[104] = 6  # point format 6 in a LAS 1.2 file (issue 42: refused at the write)
    return {
        "las_version_contradiction.las": bytes(contradiction),
        "las_huge_count.las": _set_count(good, 2**32 - 1),
        "las14_huge_count.las": _set_count(las_bytes(version="1.4"), 2**40),
        "las_count_one_more.las": _set_count(good, 401),
        "las_truncated_points.las": good[: offset + (len(good) - offset) // 2],
        "las_header_only.las": good[:offset],
        "las_nan_scale.las": bytes(nan_scale),
        "las_zero_length.las": b"",
        "laz_huge_count.laz": _set_count(laz, 2**32 - 1),
        "laz_truncated_points.laz": laz[: len(laz) * 2 // 3],
    }


def _ply_head(n: int, m: int | None, *, vtype: str = "float", ftypes: str = "uchar int") -> bytes:
    lines = ["ply", "format binary_little_endian 1.0", f"element vertex {n}"]
    lines += [f"property {vtype} {c}" for c in "xyz"]
    if m is not None:
        lines += [f"element face {m}", f"property list {ftypes} vertex_indices"]
    return ("\n".join([*lines, "end_header"]) + "\n").encode()


def _tri(a: int, b: int, c: int, *, count: str = "<u1", index: str = "<i4") -> bytes:
    return np.array([3], count).tobytes() + np.array([a, b, c], index).tobytes()


def ply_cases() -> dict[str, bytes]:
    """Binary PLY files the streamed path takes (vertex x y z first, one face list)."""
    pts = _grid(4).astype("<f4").tobytes()
    tris = _tri(0, 1, 2) + _tri(1, 3, 2)
    nan = _grid(4).astype("<f4")
    nan[1, 1] = np.nan
    inf = _grid(4).astype("<f4")
    inf[2, 0] = np.inf
    quad = np.array([4], "<u1").tobytes() + np.array([0, 1, 3, 2], "<i4").tobytes()
    return {
        "ply_bin_huge_vertex_count.ply": _ply_head(2**32 - 1, 2) + pts + tris,
        "ply_bin_huge_face_count.ply": _ply_head(4, 2**31 - 1) + pts + tris,
        "ply_bin_truncated_vertices.ply": _ply_head(4, 2) + pts[:30],
        "ply_bin_truncated_faces.ply": _ply_head(4, 2) + pts + tris[:20],
        "ply_bin_trailing_bytes.ply": _ply_head(4, 2) + pts + tris + b"garbage!",
        "ply_bin_index_out_of_range.ply": _ply_head(4, 2) + pts + _tri(0, 1, 2) + _tri(1, 9, 2),
        "ply_bin_negative_index.ply": _ply_head(4, 2) + pts + _tri(0, 1, 2) + _tri(1, -3, 2),
        "ply_bin_float_index.ply": _ply_head(4, 1, ftypes="uchar float") + pts
        + np.array([3], "<u1").tobytes() + np.array([0, 1, 1.5], "<f4").tobytes(),
        "ply_bin_quad_then_triangle.ply": _ply_head(4, 2) + pts + quad + _tri(0, 1, 2),
        "ply_bin_nan.ply": _ply_head(4, 2) + nan.tobytes() + tris,
        "ply_bin_inf.ply": _ply_head(4, 2) + inf.tobytes() + tris,
        "ply_bin_no_points.ply": _ply_head(0, 0),
        "ply_bin_zero_length.ply": b"",
        "ply_bin_header_only.ply": _ply_head(4, 2),
    }  # fmt: skip


def xyz_cases() -> dict[str, bytes]:
    """XYZ text the streamed path takes (three or more columns)."""
    return {
        "xyz_nan.xyz": b"0 0 0\n1 nan 0\n0 1 0\n1 1 0\n",
        "xyz_ragged_long.xyz": b"0 0 0\n1 0 0 5\n0 1 0\n1 1 0\n",
        "xyz_ragged_short.xyz": b"0 0 0 1\n1 0 0\n0 1 0 1\n1 1 0 1\n",
        "xyz_comments_only.xyz": b"# nothing\n# here\n",
        "xyz_header_only.xyz": b"x y z\n",
        "xyz_zero_length.xyz": b"",
        "xyz_hex_token.xyz": b"0 0 0\n1 0x10 0\n0 1 0\n1 1 0\n",
        "xyz_two_headers.xyz": b"x y z\n0 0 0\nx y z\n1 1 0\n",
    }


def all_cases(corpus: bool = True) -> dict[str, bytes]:
    """Every hostile file of the streamed formats (the corpus's too)."""
    out = {**las_cases(), **ply_cases(), **xyz_cases()}
    if corpus:
        for path in sorted(CORPUS.iterdir()):
            if path.suffix in STREAMED_SUFFIXES:
                out[f"corpus_{path.name}"] = path.read_bytes()
    return out


def write_all(dest: Path, corpus: bool = True) -> list[Path]:
    """Write :func:`all_cases` into ``dest``; the paths, sorted."""
    dest.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, data in all_cases(corpus).items():
        path = dest / name
        path.write_bytes(data)
        paths.append(path)
    return sorted(paths)


def _crc32c(data: bytes) -> int:
    """CRC-32C (Castagnoli), the checksum of every 1020-byte E57 page."""
    crc = 0xFFFFFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ (0x82F63B78 if crc & 1 else 0)
    return crc ^ 0xFFFFFFFF


def e57_bytes(n: int = 1000, path: Path | None = None) -> bytes:
    """A valid one-scan E57 file of ``n`` points written by pye57 (float32 x y z, intensity)."""
    import tempfile

    import pye57

    with tempfile.TemporaryDirectory() as tmp:
        name = str(path or Path(tmp) / "scan.e57")
        e57 = pye57.E57(name, mode="w")
        pts = _grid(n)
        fields = {"cartesianX": pts[:, 0], "cartesianY": pts[:, 1], "cartesianZ": pts[:, 2]}
        e57.write_scan_raw({**fields, "intensity": np.linspace(0, 1, n)})
        e57.close()
        return Path(name).read_bytes()


def e57_with_record_count(data: bytes, count: int) -> bytes:
    """``data`` (an E57 file) whose XML says ``recordCount="count"``, page checksums redone, so
    libE57 reads the lie as the file's truth (the XML keeps its length: indentation absorbs
    the digits)."""
    pages = [data[i : i + 1024] for i in range(0, len(data), 1024)]
    logical = b"".join(p[:1020] for p in pages)
    old = re.search(rb'recordCount="(\d+)"', logical)
    assert old is not None
    new = f'recordCount="{count}"'.encode()
    grow = len(new) - len(old[0])
    pad = logical.index(b"\n" + b" " * (grow + 1), old.end())  # an indentation after it
    logical = (logical[: old.start()] + new + logical[old.end() : pad + 1]
               + logical[pad + 1 + grow :])  # fmt: skip
    out = bytearray()
    for i in range(0, len(logical), 1020):
        page = logical[i : i + 1020]
        out += page + struct.pack(">I", _crc32c(page))
    return bytes(out)


def _dxf_lines() -> list[bytes]:
    import ezdxf

    doc = ezdxf.new("R2000")
    doc.modelspace().add_lwpolyline([(0, 0), (1, 0), (2, 1), (3, 1)])
    out = io.StringIO()
    doc.write(out)
    return out.getvalue().encode().split(b"\n")


def laz_with_chunk_count(data: bytes, count: int) -> bytes:
    """A LAZ file whose chunk table says it holds ``count`` chunks (lazrs allocated 16 bytes a
    chunk from it and aborted the process at 3e9)."""
    offset = struct.unpack_from("<I", data, 96)[0]
    table = struct.unpack_from("<q", data, offset)[0]
    buf = bytearray(data)
    struct.pack_into("<I", buf, table + 4, count)
    return bytes(buf)


def parser_cases() -> dict[str, bytes]:
    """The four files of issue 42 finding 4, each once an internal error (HTTP 500, exit 1 or
    134): a 400-digit GeoJSON integer (OverflowError), a GPX elevation of 1e308 (the noise
    estimate failed before the extent check), a DXF with non-UTF-8 bytes in a layout name
    (ezdxf's audit: AttributeError) and a LAZ whose chunk table declares 3.25e9 chunks (lazrs
    aborted: "memory allocation of 52076478480 bytes failed")."""
    big = b"9" * 400
    geojson = b'{"type":"LineString","coordinates":[[0,0],[1,' + big + b"],[2,0],[3,1]]}"
    points = b"".join(
        b'<trkpt lat="%.4f" lon="%.4f"><ele>%s</ele></trkpt>'
        % (45 + i * 1e-4, 7 + i * 1e-4, b"1e308" if i == 3 else b"10")
        for i in range(10)
    )
    gpx = (b'<?xml version="1.0"?><gpx version="1.1" creator="t" '
           b'xmlns="http://www.topografix.com/GPX/1/1"><trk><trkseg>' + points
           + b"</trkseg></trk></gpx>")  # fmt: skip
    lines = _dxf_lines()
    at = next(i for i, ln in enumerate(lines) if ln == b"Layout1")  # the first paper layout name
    dxf = b"\n".join([*lines[:at], b"\xff\xfe", *lines[at + 1 :]])
    return {
        "big_integer.geojson": geojson,
        "ele_1e308.gpx": gpx,
        "non_utf8.dxf": dxf,
        "chunk_table.laz": laz_with_chunk_count(las_bytes(5000, compress=True), 3_254_779_905),
    }
