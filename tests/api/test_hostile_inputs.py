"""Issue 24 items 3 and 4 on a live server and the CLI: a corrupt PCD ``binary_compressed`` LZF
stream is a typed 400 (not 500, not exit 1) on every channel; a 100 % full disk while an upload
is spooled is a 507 (not 500); a leading UTF-8 BOM is not content in any text format (an OBJ
keeps its first vertex)."""

from __future__ import annotations

import json
import struct
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import httpx
import numpy as np
import pytest

from tests.api.api_helpers import ROOT, LiveServer, encode, noisy_plane_cloud

BOM = b"\xef\xbb\xbf"
PARAMS = json.dumps({"lam": 1.0})


def corrupt_pcd() -> bytes:
    """4 float32 points, binary_compressed, whose LZF stream announces a 32-byte literal run
    and holds 5 bytes (lzf raises ``ValueError: error in compressed data``)."""
    stream = b"\x1f" + b"a" * 5
    header = (
        b"VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 4\nHEIGHT 1\n"
        b"VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 4\nDATA binary_compressed\n"
    )
    return header + struct.pack("<II", len(stream), 4 * 12) + stream


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "service.cli", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )


def test_a_corrupt_lzf_stream_is_a_typed_400(client: httpx.Client, tmp_path: Path) -> None:
    data = corrupt_pcd()
    files = {"file": ("bad.pcd", data)}
    answers = {
        "jobs": client.post("/v1/jobs", files=files, data={"params": PARAMS}),
        "smooth": client.post("/v1/smooth", files=files, data={"params": PARAMS}),
        "info": client.post("/v1/info", files=files),
    }
    for channel, r in answers.items():
        assert r.status_code == 400, (channel, r.text)
        body = r.json()
        assert body["code"] == "format-error", (channel, body)
        assert "corrupt LZF" in body["detail"], (channel, body)
    path = tmp_path / "bad.pcd"
    path.write_bytes(data)
    for args in (["smooth", str(path), "-o", str(tmp_path / "out.pcd")], ["info", str(path)]):
        done = _cli(*args)
        assert done.returncode == 3, (args, done.stderr)  # EXIT_INPUT
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1 and "corrupt LZF" in lines[0], done.stderr


# --------------------------------------------------------------------------- UTF-8 BOM

_POINTS = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 1.0]])
_TEXT_FILES = {
    "obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 1\n",
    "xyz": b"0 0 0\n1 0 0\n0 1 0\n1 1 1\n",
    "off": b"OFF\n4 0 0\n0 0 0\n1 0 0\n0 1 0\n1 1 1\n",
    "ply": b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
    b"property float z\nend_header\n0 0 0\n1 0 0\n0 1 0\n1 1 1\n",
    "pcd": b"VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 4\nHEIGHT 1\n"
    b"POINTS 4\nDATA ascii\n0 0 0\n1 0 0\n0 1 0\n1 1 1\n",
    "json": json.dumps({"points": _POINTS.tolist()}).encode(),
    "geojson": b'{"type":"LineString","coordinates":[[4,50,0],[4.001,50,0],[4,50.001,0],'
    b"[4.001,50.001,1]]}",
    "gpx": b'<?xml version="1.0" encoding="UTF-8"?>\n<gpx version="1.1" creator="t" '
    b'xmlns="http://www.topografix.com/GPX/1/1"><trk><trkseg><trkpt lat="50.0" lon="4.0"/>'
    b'<trkpt lat="50.0" lon="4.001"/><trkpt lat="50.001" lon="4.0"/>'
    b'<trkpt lat="50.001" lon="4.001"/></trkseg></trk></gpx>',
    "dxf": b"0\nSECTION\n2\nENTITIES\n"
    + b"".join(
        b"0\nLINE\n8\n0\n10\n%d\n20\n%d\n30\n0\n11\n%d\n21\n%d\n31\n0\n" % seg
        for seg in ((0, 0, 1, 0), (1, 0, 0, 1), (0, 1, 1, 1))
    )
    + b"0\nENDSEC\n0\nEOF\n",
}


@pytest.mark.parametrize("fmt", sorted(_TEXT_FILES))
def test_a_utf8_bom_is_not_content(client: httpx.Client, fmt: str) -> None:
    """The same file with and without a BOM: the same points on /v1/info (preview arrays)."""
    plain = _TEXT_FILES[fmt]
    seen = []
    for data in (plain, BOM + plain):
        r = client.post("/v1/info", files={"file": (f"f.{fmt}", data)}, params={"preview": True})
        assert r.status_code == 200, (fmt, r.text)
        seen.append(r.json())
    assert seen[0]["n_points"] == seen[1]["n_points"] == 4, seen
    assert seen[0]["preview"] == seen[1]["preview"]


def test_an_obj_with_a_bom_keeps_its_first_vertex(client: httpx.Client, tmp_path: Path) -> None:
    """The issue's case (no faces): four vertices, first one first, on the CLI and /v1/smooth."""
    data = BOM + _TEXT_FILES["obj"]
    path = tmp_path / "bom.obj"
    path.write_bytes(data)
    done = _cli("info", str(path), "--compact")
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["n_points"] == 4
    r = client.post(
        "/v1/smooth", files={"file": ("bom.obj", data)}, data={"params": json.dumps({"lam": 1e9})}
    )
    assert r.status_code == 200, r.text
    text = r.content.decode("utf-8-sig")  # unchanged output is the input's bytes, BOM included
    rows = [ln.split()[1:] for ln in text.splitlines() if ln.startswith("v ")]
    np.testing.assert_allclose(np.array(rows, dtype=float), _POINTS, atol=1e-9)


# --------------------------------------------------------------------------- full disk


@pytest.fixture
def small_fs(tmp_path: Path) -> Iterator[Path]:
    """A 24 MiB tmpfs mounted for the test (root only), unmounted after."""
    mnt = tmp_path / "fs"
    mnt.mkdir()
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=24m", "tmpfs", str(mnt)], capture_output=True
    )
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.decode().strip()}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


def _fill(directory: Path) -> Path:
    filler = directory / "filler"
    with open(filler, "wb", buffering=0) as fh:
        for chunk in (65536, 4096, 512, 1):
            try:
                while True:
                    fh.write(b"\0" * chunk)
            except OSError:
                continue
    return filler


def test_a_full_disk_while_spooling_is_507(
    small_fs: Path, make_server: Callable[..., LiveServer]
) -> None:
    """At 100 % full (past ``min_free_bytes``' own check): 507 storage-full for a multipart
    upload and an inline JSON body, no spool file left; space back: 202."""
    live = make_server(data_dir=small_fs / "data", GEOSMOOTH_MIN_FREE_BYTES="0")
    cloud = noisy_plane_cloud(20_000, seed=8)
    upload = {"file": ("c.xyz", encode("xyz", cloud, None))}
    inline = {"geometry": {"points": cloud.tolist()}, "params": {"lam": 1.0}}
    filler = _fill(small_fs)
    with live.client(timeout=120) as c:
        answers = [
            c.post("/v1/jobs", files=upload, data={"params": PARAMS}),
            c.post("/v1/jobs", json=inline),
            c.post("/v1/info", files=upload),
        ]
        for r in answers:
            assert r.status_code == 507, r.text
            assert r.json()["code"] == "storage-full"
            assert str(small_fs) not in r.text
        assert not list((live.data_dir / "spool").glob("upload-*"))
        filler.unlink()
        again = c.post("/v1/jobs", files=upload, data={"params": PARAMS})
        assert again.status_code == 202, again.text


# --------------------------------------------------------------------------- CLI: one line


def _gpx(lat: str, lon: str) -> bytes:
    return (
        '<?xml version="1.0"?>\n<gpx version="1.1" creator="t" '
        'xmlns="http://www.topografix.com/GPX/1/1"><trk><trkseg>'
        f'<trkpt lat="{lat}" lon="{lon}"/><trkpt lat="50.0" lon="4.001"/>'
        '<trkpt lat="50.001" lon="4.002"/></trkseg></trk></gpx>'
    ).encode()


def _las_with_scale(scale: float) -> bytes:
    import io

    import laspy

    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales, header.offsets = np.array([0.001] * 3), np.zeros(3)
    las = laspy.LasData(header)
    rng = np.random.default_rng(0)
    las.x, las.y, las.z = rng.uniform(0, 1, 50), rng.uniform(0, 1, 50), rng.normal(0, 0.01, 50)
    buf = io.BytesIO()
    las.write(buf)
    data = bytearray(buf.getvalue())
    data[131:155] = struct.pack("<3d", scale, scale, scale)
    return bytes(data)


@pytest.mark.parametrize(
    ("name", "data"),
    [
        ("lat.gpx", _gpx("1e308", "1e308")),
        ("nan.gpx", _gpx("nan", "4")),
        ("pole.gpx", _gpx("91", "4")),
        ("zero.las", _las_with_scale(0.0)),
        ("nan.las", _las_with_scale(float("nan"))),
    ],
)
def test_the_cli_error_is_one_line_without_warnings(tmp_path: Path, name: str, data: bytes) -> None:
    path = tmp_path / name
    path.write_bytes(data)
    for args in (["info", str(path)], ["smooth", str(path), "-o", str(tmp_path / f"o-{name}")]):
        done = _cli(*args)
        assert done.returncode == 3, (args, done.stderr)  # EXIT_INPUT: a malformed file
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("geosmooth: error:"), done.stderr
        assert "Warning" not in done.stderr


def test_an_r12_dxf_without_header_is_smoothed(client: httpx.Client) -> None:
    """Found by the hostile corpus: the result of a flat R12 DXF (no HEADER section) was written
    as LWPOLYLINE, which R12 has not (500 on /v1/smooth, internal-error for a job)."""
    r = client.post(
        "/v1/smooth",
        files={"file": ("r12.dxf", _TEXT_FILES["dxf"])},
        data={"params": json.dumps({"lam": 1.0})},
    )
    assert r.status_code == 200, r.text
    from service.io import read_geometry as read

    before = read(_TEXT_FILES["dxf"], "dxf").geometry.points
    after = read(r.content, "dxf").geometry.points
    assert after.shape == before.shape and np.all(np.isfinite(after))
    assert not np.allclose(after, before)  # it did smooth
