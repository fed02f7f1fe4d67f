"""Issue 41 item 3 and 5: a projected LAS reprojected like PDAL's ``a_srs``/``out_srs``
(checked against pyproj), the CRS named in the notes, ``info``'s file summary (checked against
laspy), and the header record of what smoothed an output."""

from __future__ import annotations

import datetime
import io
import json
import subprocess
import sys
from pathlib import Path

import laspy
import numpy as np
import pyproj
import pytest

from service.io import read_geometry, write_geometry
from service.io.dispatch import output_notes
from tests.cli.conftest import REPO


def _utm_las(n: int = 2000, crs: int | None = 32632, fmt: int = 6) -> bytes:
    rng = np.random.default_rng(4)
    header = laspy.LasHeader(point_format=fmt, version="1.4" if fmt >= 6 else "1.2")
    if crs is not None:
        header.add_crs(pyproj.CRS.from_epsg(crs))
    header.scales = np.array([0.001] * 3)
    header.offsets = np.array([500000.0, 5000000.0, 0.0])
    las = laspy.LasData(header)
    las.x = 500000 + rng.random(n) * 110
    las.y = 5000000 + rng.random(n) * 110
    las.z = 10 + rng.normal(0, 0.02, n)
    las.classification = np.where(rng.random(n) < 0.6, 2, 5).astype(np.uint8)
    las.intensity = (rng.random(n) * 300).astype(np.uint16)
    buf = io.BytesIO()
    las.write(buf)
    return buf.getvalue()


@pytest.mark.parametrize(
    ("option", "epsg"), [(25832, 25832), ("EPSG:32633", 32633), ("utm", 32632)]
)
@pytest.mark.parametrize("fmt", [6, 1])
def test_a_projected_las_is_reprojected_as_pyproj_does(option: object, epsg: int, fmt: int) -> None:
    data = _utm_las(fmt=fmt)
    doc = read_geometry(data, "las")
    out = laspy.read(io.BytesIO(write_geometry(doc, "las", crs=option)))
    src = laspy.read(io.BytesIO(data))
    to = pyproj.Transformer.from_crs(32632, epsg, always_xy=True)
    x, y = to.transform(np.asarray(src.x), np.asarray(src.y))
    assert out.header.parse_crs().to_epsg() == epsg
    assert np.abs(np.asarray(out.x) - x).max() <= 0.0005 + 1e-9  # half the file's scale
    assert np.abs(np.asarray(out.y) - y).max() <= 0.0005 + 1e-9
    assert np.array_equal(out.Z, src.Z) and np.array_equal(out.intensity, src.intensity)
    assert np.array_equal(out.classification, src.classification)
    back = pyproj.Transformer.from_crs(epsg, 32632, always_xy=True)
    bx, by = back.transform(np.asarray(out.x), np.asarray(out.y))  # the round trip
    assert np.abs(bx - np.asarray(src.x)).max() < 0.002 and np.abs(by - src.y).max() < 0.002
    notes = output_notes(doc, "las", option)
    assert any(f"reprojected from EPSG:32632 to EPSG:{epsg}" in n for n in notes)


def test_a_projected_las_to_ply_records_the_crs_and_a_las_without_one_is_refused() -> None:
    doc = read_geometry(_utm_las(), "las")
    ply = write_geometry(doc, "ply", crs="utm")
    assert b"comment crs EPSG:32632 (WGS 84 / UTM zone 32N)" in ply
    with pytest.raises(ValueError, match="not a projected CRS"):
        write_geometry(doc, "las", crs=4326)
    bare = read_geometry(_utm_las(crs=None), "las")
    with pytest.raises(ValueError, match="CRS is known"):
        write_geometry(bare, "las", crs=32632)


def test_geographic_input_names_the_utm_zone_it_chose() -> None:
    gpx = (b'<?xml version="1.0"?><gpx version="1.1" creator="t" '
           b'xmlns="http://www.topografix.com/GPX/1/1"><trk><trkseg>'
           + b"".join(b'<trkpt lat="50.%d" lon="4.%d"/>' % (i, i) for i in range(1, 6))
           + b"</trkseg></trk></gpx>")  # fmt: skip
    doc = read_geometry(gpx, "gpx")
    assert output_notes(doc, "las", "utm")[-1] == (
        "LAS gets easting/northing in EPSG:32631 (WGS 84 / UTM zone 31N), not longitude/latitude"
    )


def _cli(*args: object) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "service.cli", *map(str, args)], cwd=REPO,
                          capture_output=True, text=True, timeout=300, check=False)  # fmt: skip


def test_info_shows_crs_point_format_dimensions_classes_and_bounds(tmp_path: Path) -> None:
    path = tmp_path / "scan.las"
    path.write_bytes(_utm_las())
    res = _cli("info", path)
    assert res.returncode == 0, res.stderr
    facts = json.loads(res.stdout)["file"]
    las = laspy.read(path)
    assert facts["crs"] == {"epsg": 32632, "name": "WGS 84 / UTM zone 32N", "unit": "metre",
                            "projected": True}  # fmt: skip
    assert facts["point_format"] == 6 and facts["las_version"] == "1.4"
    assert [d["name"] for d in facts["dimensions"]] == list(las.point_format.dimension_names)
    codes, counts = np.unique(las.classification, return_counts=True)
    assert facts["classes"] == {str(c): int(k) for c, k in zip(codes, counts, strict=True)}
    assert facts["bounds"]["min"] == [float(las.x.min()), float(las.y.min()), float(las.z.min())]
    assert facts["scales"] == [0.001] * 3


def test_a_smoothed_las_records_what_smoothed_it(tmp_path: Path) -> None:
    src, out = tmp_path / "scan.las", tmp_path / "out.las"
    src.write_bytes(_utm_las())
    res = _cli("smooth", src, "-o", out, "--rms", "0.01", "-q")
    assert res.returncode == 0, res.stderr
    header = laspy.read(out).header
    assert header.generating_software.startswith("geosmooth ")
    assert header.system_identifier == "geosmooth smoothing"
    assert header.creation_date == datetime.date.today()


def test_notes_are_true_for_the_output_format() -> None:
    """Issue 41 item 8: a GPX's waypoints and times are named as not written to a LAS (its
    gps_time stays 0), not "kept" there; a GPX output keeps them."""
    gpx = (b'<?xml version="1.0"?><gpx version="1.1" creator="t" '
           b'xmlns="http://www.topografix.com/GPX/1/1"><wpt lat="50.5" lon="4.5"/><trk><trkseg>'
           + b"".join(b'<trkpt lat="50.%d" lon="4.%d"><time>2026-01-01T00:00:0%dZ</time>'
                      b"</trkpt>" % (i, i, i) for i in range(1, 6))
           + b"</trkseg></trk></gpx>")  # fmt: skip
    doc = read_geometry(gpx, "gpx")
    las = output_notes(doc, "las")
    assert "LAS keeps no GPX waypoints: 1 not written" in las
    assert "LAS gets no GPX times: the <time> of 5 points not written" in las
    assert not any("kept" in n and "waypoint" in n for n in las)
    assert "kept 1 waypoints as they are" in output_notes(doc, "gpx")
    out = laspy.read(io.BytesIO(write_geometry(doc, "las")))
    assert "gps_time" not in out.point_format.dimension_names or not np.any(out.gps_time)


def test_in_crs_gives_a_bare_las_its_crs_and_feeds_crs(tmp_path: Path) -> None:
    """``--in-crs`` (PDAL's a_srs): recorded in the output, and the source of ``--crs``."""
    src = tmp_path / "bare.las"
    src.write_bytes(_utm_las(crs=None, fmt=1))
    out = tmp_path / "out.las"
    res = _cli("smooth", src, "-o", out, "--in-crs", "32632", "--crs", "25832", "--rms", "0.01")
    assert res.returncode == 0, res.stderr
    assert "reprojected from EPSG:32632 to EPSG:25832" in res.stderr
    assert laspy.read(out).header.parse_crs().to_epsg() == 25832
    res = _cli("smooth", src, "-o", out, "--in-crs", "32632", "--rms", "0.01", "-q")
    assert res.returncode == 0 and laspy.read(out).header.parse_crs().to_epsg() == 32632
    sphere = REPO / "service" / "samples" / "noisy-sphere.ply"
    for source, code in ((src, "99999999"), (sphere, "32632")):
        res = _cli("smooth", source, "-o", tmp_path / "x.ply", "--in-crs", code)
        assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1, res.stderr
        assert "--in-crs" in res.stderr
